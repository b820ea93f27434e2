"""Reading the project's ``.npz`` files (motion.npz, robot.npz, servo_goals.npz) with one
behaviour: no pickles, every array read at once, sizes bounded before anything is allocated, and
an :class:`~motok_robot.errors.InputError` naming the file (and the field) when it is missing,
too large or is not a readable ``.npz``.  Light: numpy only.

Bounds (:mod:`motok_robot.limits`): the file on disk (``file_bytes``) and the arrays once
decompressed (``inflated_bytes``, from the ``.npy`` headers and the zip directory, checked before
reading), so a small archive that inflates to gigabytes is refused up front.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.limits import LIMITS, check_file_size, limit


def _member_field(name: str) -> str:
    return name[:-4] if name.endswith(".npy") else name


def check_npz_sizes(path: str | Path, what: str = ".npz file") -> None:
    """Refuse ``path`` when it is not a zip archive of ``.npy`` arrays, when an array holds
    Python objects or has a corrupt header, or when its size on disk or decompressed is above
    the limits; reads only the zip directory and the array headers."""
    path = Path(path)
    check_file_size(path, what)
    if not zipfile.is_zipfile(path):
        with open(path, "rb") as handle:
            start = handle.read(8)
        kind = "is empty" if not start else f"starts with {start!r}"
        raise InputError(f"{path}: not a readable .npz file: not a zip archive of .npy arrays (the file {kind})")
    bound = limit("inflated_bytes")
    total = 0
    try:
        with zipfile.ZipFile(path) as archive:
            for info in archive.infolist():
                field = _member_field(info.filename)
                if info.file_size > bound:
                    raise InputError(f"{path}: field '{field}' inflates to {info.file_size:,} bytes, above the limit "
                                     f"of {bound:,.0f} ({LIMITS['inflated_bytes'].env}=N or --limit inflated_bytes=N)")
                with archive.open(info) as member:
                    try:
                        version = np.lib.format.read_magic(member)
                        if version == (1, 0):
                            shape, _, dtype = np.lib.format.read_array_header_1_0(member)
                        elif version in ((2, 0), (3, 0)):
                            shape, _, dtype = np.lib.format.read_array_header_2_0(member)
                        else:
                            raise ValueError(f"unsupported .npy version {version}")
                    except InputError:
                        raise
                    except Exception as exc:  # noqa: BLE001 - any malformed header is an input problem
                        raise InputError(f"{path}: field '{field}' is not a readable .npy array (corrupt header: "
                                         f"{' '.join(str(exc).split())[:200]})") from None
                if dtype.hasobject:
                    raise InputError(f"{path}: field '{field}' holds Python objects (pickled data), which are never "
                                     "loaded: store numbers or strings")
                nbytes = math.prod(int(n) for n in shape) * max(dtype.itemsize, 1)
                total += max(nbytes, info.file_size)
                if total > bound:
                    raise InputError(f"{path}: field '{field}' ({'x'.join(map(str, shape)) or 'scalar'} {dtype}) "
                                     f"brings the decompressed arrays to {total:,} bytes, above the limit of "
                                     f"{bound:,.0f} ({LIMITS['inflated_bytes'].env}=N or --limit inflated_bytes=N)")
    except InputError:
        raise
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError) as exc:
        raise InputError(f"{path}: not a readable .npz file ({' '.join(str(exc).split())[:200]})") from None


def read_npz_fields(path: str | Path, what: str = ".npz file") -> dict[str, np.ndarray]:
    """All arrays of ``path`` as ``{name: array}``; ``what`` names the kind of file in errors."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: {what} not found")
    check_npz_sizes(path, what)
    try:
        with np.load(path, allow_pickle=False) as data:
            fields = {key: data[key] for key in data.files}
    except Exception as exc:  # noqa: BLE001 - truncated, foreign or pickled content: all input problems
        raise InputError(f"{path}: not a readable .npz file ({' '.join(str(exc).split())[:200]})") from None
    reject_complex(fields, path)
    return fields


def reject_complex(fields: dict, path: str | Path) -> None:
    """No project file holds complex numbers: casting them to float would drop the imaginary part
    silently, so a complex field is an InputError naming it."""
    for key, value in fields.items():
        if np.asarray(value).dtype.kind == "c":
            raise InputError(f"{path}: field '{key}' holds complex numbers ({np.asarray(value).dtype}); "
                             "real numbers are expected")


def scalar_field(fields: dict, key: str, path: str | Path, kind=float):
    """``fields[key]`` as one number (``kind``), InputError naming the file and field otherwise."""
    value = np.asarray(fields[key])
    if value.size != 1 or not (np.issubdtype(value.dtype, np.number) or value.dtype == bool):
        raise InputError(f"{path}: field '{key}' must be one number, got an array of shape {value.shape} "
                         f"({value.dtype})")
    try:
        return kind(value.reshape(()).item())
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{path}: field '{key}' must be one number, got {value.reshape(()).item()!r}") from None

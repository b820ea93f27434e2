# Size (422 lines): every source kind's discovery and loading, so the kinds stay uniform.
"""Finding the clips of a data source (folder or ``.tar.xz`` / ``.zip`` archive) and loading them.

A source is ``KIND=PATH``. :func:`iter_jobs` walks PATH (archives are streamed member by
member with :mod:`tarfile` / :mod:`zipfile`; nothing is extracted to disk) and yields
picklable :class:`Job` s holding the text of the file(s) one clip needs; :func:`run_job`
(run in a worker process) turns a job into :class:`~motok_robot.data.clip.Clip` s with
texts.  Files that a kind does not use (licences, READMEs, Bandai's JSON sidecars) are
ignored; files that it should use but cannot read become skipped-file entries.

Kinds:

========== ===================================================================================
bandai     Bandai Namco Research Motion Dataset 1/2 BVH (``dataset-N_content_style_NNN.bvh``)
cmu        CMU ASF/AMC (``SS.asf`` + ``SS_TT.amc``), texts from ``cmu-descriptions.csv``
deepmimic  DeepMimic JSON motions (``*.txt`` / ``*.json``); ``cmu/SS_TT`` clips get CMU texts
acrnn      acRNN BVH (43-joint ``standard.bvh`` skeleton), genre from the folder
bvh        any BVH, with ``--map FILE`` (joint-map JSON), texts from ``--texts``
asf        any ASF/AMC pair (``--map`` optional: default CMU names), texts from ``--texts``
humanml3d  a HumanML3D folder (``new_joint_vecs``, ``new_joints``, ``texts``, splits)
========== ===================================================================================
"""

from __future__ import annotations

import re
import tarfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Iterator

from motok_robot.data import texts as T
from motok_robot.data.clip import Clip
from motok_robot.errors import InputError

KINDS = ("bandai", "cmu", "deepmimic", "acrnn", "bvh", "asf", "humanml3d")

LICENCES = {
    "bandai": "CC BY-NC 4.0 (Bandai Namco Research Inc.; non-commercial, attribution)",
    "cmu": "CMU Graphics Lab Motion Capture Database: free for all uses (mocap.cs.cmu.edu, NSF EIA-0196217)",
    "deepmimic": "MIT (DeepMimic (c) 2018 Xue Bin Peng; converted CMU motions (c) 2021 arpspoof)",
    "acrnn": "MIT (c) 2018 the authors of Auto-Conditioned Recurrent Networks",
}
#: acRNN genre frame rates from the dataset's readme.txt ("salsa framerate 60"); the BVH
#: headers all say 120 fps, which makes salsa steps twice too fast (feet step at ~2 Hz).
ACRNN_DEFAULT_FPS = {"salsa": 60.0, "indian": 120.0, "martial": 120.0}
#: every acRNN file starts with the same 9-frame lead-in: frame 0 an unrelated pose (joints
#: jump 0.4-1.5 m to frame 1), frames 1-8 a blend whose joint speeds (9-24, 4, 0.5, 2, 1 m/s
#: at the file rate) follow one fixed pattern in all 43 files; real motion starts at frame 9
ACRNN_LEAD_IN_FRAMES = 9

_BANDAI_RE = re.compile(r"dataset-(\d+)_([a-z-]+?)_([a-z-]+)_(\d+)$")


def content_of(clip_id: str) -> str:
    """What a prepared clip shows, for matching sets by content: the Bandai content of the file
    name (``walk-turn-right``; left and right swapped for a ``mirror/`` clip, whose motion is
    mirrored), otherwise the source (``cmu``, ``deepmimic`` ...)."""
    mirrored = clip_id.startswith("mirror/")
    base = clip_id.removeprefix("mirror/")
    m = _BANDAI_RE.search(base.rsplit("/", 1)[-1]) if base.startswith("bandai/") else None
    if not m:
        return base.split("/", 1)[0]
    content = m.group(2)
    if mirrored:
        content = "-".join({"left": "right", "right": "left"}.get(w, w) for w in content.split("-"))
    return content


@dataclass
class SourceOptions:
    """What the CLI passes to every job of a source."""

    joint_map: dict | None = None  # parsed --map (bvh/asf)
    text_index: dict[str, list[str]] = field(default_factory=dict)
    cmu_descriptions: dict[str, dict] = field(default_factory=dict)
    asf_fps: float = 120.0


@dataclass
class Job:
    kind: str
    file: str  # for messages: path or "archive:member"
    contents: dict[str, str]  # role -> file text ("bvh", "asf", "amc", "json")
    meta: dict = field(default_factory=dict)


@dataclass
class Skipped:
    file: str
    reason: str


# ----------------------------------------------------------------------------- members

def _members(path: Path) -> Iterator[tuple[str, object]]:
    """``(relative name, reader)`` for files under a folder or inside an archive; reader() -> bytes."""
    if path.is_dir():
        for p in sorted(path.rglob("*")):
            if p.is_file():
                yield p.relative_to(path).as_posix(), p.read_bytes
        return
    name = path.name.lower()
    if name.endswith(".zip"):
        try:
            zf = zipfile.ZipFile(path)
        except zipfile.BadZipFile as exc:
            raise InputError(f"{path}: not a readable zip archive ({exc})") from None
        with zf:
            for info in zf.infolist():
                if not info.is_dir():
                    yield info.filename, (lambda i=info: zf.read(i))
        return
    if any(name.endswith(s) for s in (".tar", ".tar.xz", ".txz", ".tar.gz", ".tgz", ".tar.bz2")):
        try:
            tf = tarfile.open(path, mode="r|*")
        except (tarfile.TarError, OSError) as exc:
            raise InputError(f"{path}: not a readable tar archive ({exc})") from None
        with tf:
            try:
                for info in tf:
                    if info.isfile():
                        fh = tf.extractfile(info)
                        data = fh.read() if fh is not None else b""
                        yield info.name, (lambda d=data: d)
            except (tarfile.TarError, EOFError, OSError) as exc:
                raise InputError(f"{path}: archive is damaged or truncated ({exc})") from None
        return
    if path.is_file():
        yield path.name, path.read_bytes
        return
    raise FileNotFoundError(f"{path}: no such file or folder")


def _decode(data: bytes) -> str:
    return data.decode("utf-8", errors="replace")


def _label(path: Path, member: str) -> str:
    return str(path / member) if path.is_dir() else f"{path}:{member}"


# ----------------------------------------------------------------------------- discovery

def iter_jobs(kind: str, path: str | Path, options: SourceOptions) -> Iterator[Job | Skipped]:
    """Jobs (or Skipped entries) for one source. Raises InputError for an unusable PATH/kind."""
    if kind not in KINDS:
        raise InputError(f"unknown source kind {kind!r}; use one of {', '.join(KINDS)}")
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or folder (source {kind})")
    if kind == "humanml3d":
        yield from _humanml3d_jobs(path)
        return
    if kind in ("cmu", "asf"):
        yield from _asf_jobs(kind, path, options)
        return
    readme_fps: dict[str, float] = {}
    if kind == "acrnn" and path.is_dir():  # read the frame rates before any BVH
        for readme in sorted(path.rglob("readme.txt")):
            readme_fps.update(_acrnn_readme(readme.read_text(errors="replace")))
    for member, read in _members(path):
        pp = PurePosixPath(member)
        low = pp.name.lower()
        if kind == "acrnn" and low == "readme.txt":
            readme_fps.update(_acrnn_readme(_decode(read())))
            continue
        if kind in ("bandai", "acrnn", "bvh") and low.endswith(".bvh"):
            if kind == "acrnn" and low == "standard.bvh":
                continue  # the rest skeleton of acRNN, no motion
            meta = {"member": member, "readme_fps": dict(readme_fps)}
            yield Job(kind, _label(path, member), {"bvh": _decode(read())}, meta)
        elif kind == "deepmimic" and low.endswith((".txt", ".json")) and not low.startswith(("license", "readme")):
            yield Job(kind, _label(path, member), {"json": _decode(read())}, {"member": member})


def _acrnn_readme(text: str) -> dict[str, float]:
    """``{"salsa": 60.0, ...}`` from acRNN's readme.txt lines ``salsa  framerate 60``."""
    out = {}
    for line in text.splitlines():
        m = re.match(r"\s*(\w+)\s+framerate\s+([\d.]+)", line, re.I)
        if m:
            out[m.group(1).lower()] = float(m.group(2))
    return out


def skeleton_for(amc_stem: str, asf_stems) -> str | None:
    """The skeleton (ASF stem) of a motion file: the longest ASF stem that is a prefix of
    ``amc_stem`` ending at a separator (``HDM_tr`` for ``HDM_tr_squat1Reps_001_120``, ``01`` for
    ``01_02``; never ``1`` for ``10_01``), else the only ASF of the folder, else None."""
    best = None
    for stem in asf_stems:
        if amc_stem == stem or (amc_stem.startswith(stem) and not amc_stem[len(stem)].isalnum()):
            if best is None or len(stem) > len(best):
                best = stem
    if best is None and len(asf_stems) == 1:
        best = next(iter(asf_stems))
    return best


def _asf_jobs(kind: str, path: Path, options: SourceOptions) -> Iterator[Job | Skipped]:
    """Pair every AMC with the ASF of its folder (:func:`skeleton_for`: the longest ASF name that
    prefixes the AMC's, ``SS_TT.amc`` -> ``SS.asf``, else the only ASF). An AMC is paired as soon
    as a matching ASF has been read (in sorted order an ASF comes before the AMC files it prefixes);
    one read before its ASF waits for it."""
    asfs: dict[str, dict[str, str]] = {}  # folder -> {stem: text}
    pending: list[tuple[str, str]] = []  # (member, amc text) waiting for their ASF

    def pair(member: str, text: str) -> Job | Skipped | None:
        pp = PurePosixPath(member)
        folder = asfs.get(str(pp.parent), {})
        asf_name = skeleton_for(pp.stem, folder)
        if asf_name is None:
            return None
        meta = {"member": member, "asf": str(pp.parent / (asf_name + ".asf"))}
        return Job(kind, _label(path, member), {"asf": folder[asf_name], "amc": text}, meta)

    for member, read in _members(path):
        low = member.lower()
        pp = PurePosixPath(member)
        if low.endswith(".asf"):
            asfs.setdefault(str(pp.parent), {})[pp.stem] = _decode(read())
            still = []
            for m, text in pending:
                job = pair(m, text)
                if job is None:
                    still.append((m, text))
                else:
                    yield job
            pending = still
        elif low.endswith(".amc"):
            text = _decode(read())
            job = pair(member, text)
            if job is None:
                pending.append((member, text))
            else:
                yield job
    for m, _text in pending:
        folder = asfs.get(str(PurePosixPath(m).parent), {})
        why = ("no .asf skeleton file in its folder" if not folder else
               f"several .asf files ({sorted(folder)[:5]}{' ...' if len(folder) > 5 else ''}) and none whose name "
               "is a prefix of its own")
        yield Skipped(_label(path, m), why)


def humanml3d_root(path: str | Path, workdir: str | Path | None = None) -> Path:
    """The folder holding ``new_joint_vecs/`` under ``path``.

    An archive is extracted into ``workdir`` first (HumanML3D needs three files per clip from
    different folders, so it is not streamed); the caller owns ``workdir`` and deletes it.
    """
    path = Path(path)
    if not path.is_dir():
        if workdir is None:
            raise InputError(f"{path}: a HumanML3D source must be a folder or an archive (with a work folder)")
        dest = Path(workdir)
        dest.mkdir(parents=True, exist_ok=True)
        _extract(path, dest)
        path = dest
    if (path / "new_joint_vecs").is_dir():
        return path
    cands = sorted(p.parent for p in path.rglob("new_joint_vecs") if p.is_dir())
    if not cands:
        raise InputError(f"{path}: not a HumanML3D folder (no new_joint_vecs/ inside)")
    return cands[0]


def _extract(archive: Path, dest: Path) -> None:
    name = archive.name.lower()
    try:
        if name.endswith(".zip"):
            with zipfile.ZipFile(archive) as zf:
                zf.extractall(dest)  # zipfile drops absolute paths and ".." components
        else:
            with tarfile.open(archive, "r:*") as tf:
                tf.extractall(dest, filter="data")  # refuses links/paths outside dest
    except (tarfile.TarError, zipfile.BadZipFile, OSError, EOFError) as exc:
        raise InputError(f"{archive}: cannot extract archive ({exc})") from None


def _humanml3d_jobs(path: Path) -> Iterator[Job | Skipped]:
    root = humanml3d_root(path)
    from motok_robot.data import humanml3d

    for cid in humanml3d.list_ids(root):
        yield Job("humanml3d", str(root / "new_joint_vecs" / f"{cid}.npy"), {}, {"root": str(root), "hid": cid})


# ----------------------------------------------------------------------------- loading

def run_job(job: Job, options: SourceOptions) -> list[Clip]:
    """Load the clip(s) of a job and attach texts, labels and grouping keys.

    Raises InputError (naming the file and the problem) when the file cannot be used.
    """
    kind = job.kind
    member = job.meta.get("member", "")
    stem = PurePosixPath(member).stem if member else Path(job.file).stem
    if kind == "bandai":
        from motok_robot.data import bvh

        m = _BANDAI_RE.search(stem)
        if not m:
            raise InputError(f"{job.file}: file name is not dataset-N_content_style_NNN.bvh")
        ds, content, style, take = m.groups()
        cid = f"bandai/{stem}"
        texts = T.bandai_texts(content, style, cid)  # raises for unknown content/style
        clip = bvh.load_clip(job.file, "bandai", cid, "bandai", LICENCES["bandai"], text=job.contents["bvh"])
        clip.texts = texts
        clip.labels = {"content": content, "style": style, "take": int(take), "group": f"bandai/{ds}_{content}_{style}"}
        return [clip]
    if kind == "acrnn":
        from motok_robot.data import bvh

        parts = PurePosixPath(member).parts
        genre = parts[-2].lower() if len(parts) >= 2 else "dance"
        fps = job.meta.get("readme_fps", {}).get(genre) or ACRNN_DEFAULT_FPS.get(genre)
        motion = bvh.read_bvh(job.file, job.contents["bvh"])
        if motion.channels.shape[0] < 3:
            raise InputError(f"{job.file}: only {motion.channels.shape[0]} frames")
        if motion.channels.shape[0] <= ACRNN_LEAD_IN_FRAMES + 2:
            raise InputError(f"{job.file}: only {motion.channels.shape[0]} frames (the first {ACRNN_LEAD_IN_FRAMES} are a lead-in)")
        motion.channels = motion.channels[ACRNN_LEAD_IN_FRAMES:]
        joints, derived = bvh.bvh_to_joints(motion, bvh.ACRNN_MAP, bvh.ACRNN_UNITS_TO_M, bvh.ACRNN_UP, fps=fps)
        cid = f"acrnn/{genre}/{stem}"
        return [
            Clip(cid, "acrnn", LICENCES["acrnn"], joints, texts=T.acrnn_texts(genre, cid), file=job.file,
                 derived_joints=derived, labels={"genre": genre, "fps_used": fps, "group": cid})
        ]
    if kind == "bvh":
        from motok_robot.data import bvh

        if options.joint_map is None:
            raise InputError("source kind 'bvh' needs --map FILE (a joint-map JSON, see docs/data.md)")
        cid = "bvh/" + _id_from_member(member or Path(job.file).name)
        clip = bvh.load_clip(job.file, options.joint_map, cid, "bvh", "user data", text=job.contents["bvh"])
        clip.texts = T.lookup_texts(options.text_index, cid, job.file)
        clip.labels = {"group": cid}
        return [clip]
    if kind in ("cmu", "asf"):
        from motok_robot.data import asf_amc

        cid_stem = _id_from_member(member or Path(job.file).name)
        cid = f"{kind}/{cid_stem}"
        key = _cmu_key(stem)
        fps = options.asf_fps
        desc = None
        if kind == "cmu":
            info = options.cmu_descriptions.get(key or "", {})
            fps = info.get("fps") or 120.0
            desc = info.get("description")
            cid = f"cmu/{key or cid_stem}"
        jmap = options.joint_map["joints"] if (kind == "asf" and options.joint_map) else None
        up = options.joint_map["up_axis"] if (kind == "asf" and options.joint_map) else "y"
        fwd = options.joint_map.get("forward") if (kind == "asf" and options.joint_map) else None
        units = options.joint_map.get("units_to_m") if (kind == "asf" and options.joint_map) else None
        clip = asf_amc.load_clip(
            job.meta.get("asf", "skeleton.asf"), job.file, jmap, fps, up, fwd, cid, kind,
            LICENCES["cmu"] if kind == "cmu" else "user data",
            asf_text=job.contents["asf"], amc_text=job.contents["amc"], units_to_m=units,
        )
        texts = T.description_texts(desc, cid) if desc else []
        texts = texts or T.lookup_texts(options.text_index, cid, job.file)
        clip.texts = texts
        # the same CMU trial may also come converted by DeepMimic: one group keeps them in one split
        clip.labels = {**clip.labels, "description": desc, "fps_used": fps,
                       "group": f"cmu/{key}" if (kind == "cmu" and key) else cid}
        return [clip]
    if kind == "deepmimic":
        from motok_robot.data import deepmimic

        parts = PurePosixPath(member).parts
        top = parts[-2] if len(parts) >= 2 else "deepmimic"
        if "cmu" in parts or any(p.startswith("cmu") for p in parts[:-1]):
            top = "cmu"
        cid = f"deepmimic/{top}/{stem}"
        clip = deepmimic.load_clip(job.file, cid, "deepmimic", LICENCES["deepmimic"], text=job.contents["json"])
        key = _cmu_key(stem)
        if top == "cmu" and key and key in options.cmu_descriptions:
            clip.texts = T.description_texts(options.cmu_descriptions[key]["description"], cid)
        else:
            clip.texts = T.lookup_texts(options.text_index, cid, job.file) or T.deepmimic_texts(stem, cid)
        labels = {"group": f"cmu/{key}" if (top == "cmu" and key) else cid.removesuffix("_mirror")}
        if stem.endswith("_mirror"):
            labels["mirror_of"] = cid.removesuffix("_mirror")
        clip.labels = labels
        return [clip]
    if kind == "humanml3d":
        from motok_robot.data import humanml3d

        clips = humanml3d.load_clips(job.meta["root"], job.meta["hid"])
        for c in clips:
            base = job.meta["hid"].lstrip("M")
            c.labels["group"] = f"humanml3d/{base}"
            if not c.texts:
                c.texts = T.lookup_texts(options.text_index, c.id, job.file)
        return clips
    raise InputError(f"unknown source kind {kind!r}")


def _cmu_key(stem: str) -> str | None:
    m = re.match(r"^(\d+)_(\d+)$", stem)
    return f"{int(m.group(1)):02d}_{int(m.group(2)):02d}" if m else None


def _id_from_member(member: str) -> str:
    p = PurePosixPath(member)
    rel = str(p.with_suffix("")) if p.suffix else str(p)
    return re.sub(r"[^A-Za-z0-9_.\-/]", "_", rel).strip("/")


def find_cmu_descriptions(path: str | Path) -> Path | None:
    """``cmu-descriptions.csv`` inside a source folder or next to it / its archive."""
    path = Path(path)
    places = [path] if path.is_dir() else []
    places += [path.parent, path.parent.parent]
    for d in places:
        for name in ("cmu-descriptions.csv", "cmu_descriptions.csv"):
            if (d / name).is_file():
                return d / name
    return None

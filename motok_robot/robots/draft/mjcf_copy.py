"""The MJCF copy beside the TOML: the user's file with the sites the description needs (and a floor,
a ``track`` camera, an offscreen buffer, joint ranges) added; the original is never written."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.robots.draft.drafter import Drafter
from motok_robot.robots.draft.sites import Site


def parse_xml(path: Path) -> ET.ElementTree:
    try:
        return ET.parse(path, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    except ET.ParseError as exc:
        raise InputError(f"{path.name}: not valid XML: {exc}") from None


def _fix_asset_paths(root: ET.Element, src_dir: Path, out_dir: Path) -> None:
    """Point the copy's asset folders (and includes) back at the original's files."""
    comp = root.find("compiler")
    if comp is None:
        comp = ET.Element("compiler")
        comp.tail = "\n  "
        root.insert(0, comp)
    assetdir = comp.attrib.pop("assetdir", None)

    def rel(target: Path) -> str:
        return Path(os.path.relpath(target.resolve(), out_dir.resolve())).as_posix()

    for key in ("meshdir", "texturedir"):
        value = comp.get(key, assetdir)
        base = src_dir / value if value else src_dir
        comp.set(key, rel(base))
    for inc in root.iter("include"):
        f = inc.get("file")
        if f and not Path(f).is_absolute():
            inc.set("file", rel(src_dir / f))


def _fmt(v: float) -> str:
    s = f"{v:.6f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _camera_attrs(height: float, target: np.ndarray) -> dict[str, str]:
    direction = np.array([0.78, -0.62, 0.06])
    direction /= np.linalg.norm(direction)
    pos = target + 2.0 * max(height, 0.2) * direction
    f = -direction
    x = np.cross(f, [0, 0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(-f, x)
    return {"name": "track", "mode": "trackcom", "pos": " ".join(_fmt(v) for v in pos),
            "xyaxes": " ".join(_fmt(v) for v in (*x, *y)), "fovy": "45"}


def write_copy(dr: Drafter, out_xml: Path, need_sites: list[Site], add_floor: bool, add_camera: bool) -> list[str]:
    """Write the MJCF copy with the sites (and floor, camera, buffer, ranges) added. Returns what was added."""
    M = dr.M
    tree = parse_xml(dr.src)
    root = tree.getroot()
    added = []
    _fix_asset_paths(root, dr.src.parent, out_xml.parent)
    world = root.find("worldbody")
    if world is None:
        raise InputError(f"{dr.src.name}: no <worldbody>")
    xml_bodies = list(world.iter("body"))
    by_name = {b.get("name"): b for b in xml_bodies if b.get("name")}
    same_order = len(xml_bodies) == M.m.nbody - 1

    def body_elem(b: int) -> ET.Element:
        name = M.body_name(b)
        if name in by_name:
            return by_name[name]
        if same_order:
            return xml_bodies[b - 1]
        raise InputError(f"{dr.src.name}: body #{b} has no name and the copy cannot place sites in it "
                         f"(bodies from <include>/<replicate>?); name it")

    def indent_of(elem: ET.Element) -> str:
        return elem.text if elem.text and elem.text.strip() == "" else "\n  "

    def insert(parent: ET.Element, child: ET.Element) -> None:
        kids = list(parent)
        idx = next((i for i, k in enumerate(kids) if k.tag == "body"), len(kids))
        child.tail = indent_of(parent)
        if idx == len(kids) and kids:
            child.tail = kids[-1].tail
            kids[-1].tail = indent_of(parent)
        parent.insert(idx, child)

    scale = max(dr.height(), 0.2)
    for s in need_sites:
        local = dr._local(s.body, s.pos)
        size = 0.012 * scale if s.kind == "kp" else 0.008 * scale
        rgba = "1 0.3 0.1 0.7" if s.kind == "kp" else "0.1 0.9 0.2 0.9"
        e = ET.Element("site", {"name": s.name, "pos": " ".join(_fmt(v) for v in local), "type": "sphere",
                                "size": _fmt(size), "group": "4", "rgba": rgba})
        insert(body_elem(s.body), e)
    if need_sites:
        added.append(f"{len(need_sites)} sites (render group 4)")
    for j, (lo, hi) in dr.added_ranges.items():
        name = M.joint_name(j)
        elems = [e for e in root.iter() if e.tag in ("joint",) and e.get("name") == name]
        if not elems:
            raise InputError(f"{dr.src.name}: cannot find <joint name={name!r}> to give it a range")
        elems[0].set("range", f"{_fmt(lo)} {_fmt(hi)}")
        elems[0].set("limited", "true")
    if dr.added_ranges:
        added.append(f"ranges on {len(dr.added_ranges)} joints")
    if add_floor:
        floor = ET.Element("geom", {"name": "floor", "type": "plane", "size": "0 0 0.05", "rgba": "0.8 0.8 0.8 1",
                                    "contype": "1", "conaffinity": "1", "condim": "3", "friction": "1 0.005 0.0001"})
        floor.tail = indent_of(world)
        world.insert(0, floor)
        added.append("a floor plane")
        if world.find("light") is None and not any(e.tag == "light" for e in world.iter()):
            light = ET.Element("light", {"name": "sun", "pos": "0 0 3", "dir": "0 0 -1", "directional": "true"})
            light.tail = indent_of(world)
            world.insert(0, light)
            added.append("a light")
    if add_camera:
        base = body_elem(M.base)
        target = np.array([0.0, 0.0, (dr.top + min(z for _, _, z in dr.soles.values())) / 2])
        cam = ET.Element("camera", _camera_attrs(dr.height(), dr._local(M.base, target)))
        insert(base, cam)
        added.append("a 'track' camera")
    vis = root.find("visual")
    if vis is None:
        vis = ET.Element("visual")
        vis.tail = "\n  "
        root.insert(1, vis)
    glob = vis.find("global")
    if glob is None:
        glob = ET.SubElement(vis, "global")
    if float(glob.get("offwidth", 640)) < 1280 or float(glob.get("offheight", 480)) < 960:
        glob.set("offwidth", "1280")
        glob.set("offheight", "960")
        added.append("a 1280x960 offscreen buffer")
    note = ET.Comment(f" motok-robot robots add: a copy of {dr.src.name} with {', '.join(added)} added; "
                      f"asset folders point back at the original's. Edit this copy, not the original. ")
    note.tail = "\n  "
    root.insert(0, note)
    out_xml.parent.mkdir(parents=True, exist_ok=True)
    tree.write(out_xml, encoding="unicode", xml_declaration=False)
    return added

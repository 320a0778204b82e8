"""A vendor's URDF as read for ``export --onto``: its joints, its tree, where each joint's
``<origin>`` sits in the file's bytes (so that only those bytes change), and the forward
kinematics of a serial path through it.

The file is read with the standard library's expat parser (the XML as it is: no xacro),
in the encoding it declares (a byte-order mark, else its XML declaration, else UTF-8:
XML 1.0 appendix F); its text is held as UTF-8 and written back in that encoding, so
every byte outside the edits is the vendor's. Only ``<joint>`` and ``<link>`` elements
directly under ``<robot>`` count; a ``<joint>`` inside ``<transmission>`` is not a
kinematic joint. A ``planar`` or ``floating`` joint (a mobile base) is read as a joint
that moves; it may not lie between the mapped joints.
"""

from __future__ import annotations

import codecs
import re
from dataclasses import dataclass, replace
from pathlib import Path
from xml.parsers import expat

import numpy as np

from pipeline.errors import ArmsigError, one_line
from pipeline.kinematics.transforms import Array, rot_z, trans_z, transform_from_xyz_rpy

M_PER_CM = 0.01
MOVING = ("revolute", "continuous", "prismatic")
#: Joints of more than one freedom (a mobile base): read, never mapped to an arm joint.
FREE = ("planar", "floating")
KINDS = (*MOVING, *FREE, "fixed")
#: Byte-order marks and their codecs, the 4-byte ones first (UTF-32 LE starts as UTF-16 LE).
_BOMS = (
    (codecs.BOM_UTF32_LE, "utf-32-le"), (codecs.BOM_UTF32_BE, "utf-32-be"),
    (codecs.BOM_UTF8, "utf-8"), (codecs.BOM_UTF16_LE, "utf-16-le"),
    (codecs.BOM_UTF16_BE, "utf-16-be"),
)  # fmt: skip
#: Without a mark, a document's first bytes ``<?`` in a wider encoding (XML 1.0 app. F).
_WIDE = ((b"<\0?\0", "utf-16-le"), (b"\0<\0?", "utf-16-be"))
#: The most of a vendor URDF read (bytes): the largest URDFs (a humanoid's, meshes
#: referenced, not inlined) are a few hundred kilobytes.
MAX_URDF_BYTES = 64 * 2**20
#: A start tag, its attribute values may hold ``>``.
_TAG = r'(?:[^>"\']|"[^"]*"|\'[^\']*\')*'
_ORIGIN = re.compile(rb"<origin\b" + _TAG.encode() + rb"?(/?)>")  # lazy: "/" stays out
_END_ORIGIN = re.compile(rb"</origin\s*>")
_START = re.compile(rb"<joint\b" + _TAG.encode() + rb">")


@dataclass(frozen=True)
class VendorJoint:
    """One ``<joint>``: kinematics in cm, and where its ``<origin>`` is in the file."""

    name: str
    type: str
    parent: str
    child: str
    origin: Array  # (4, 4) cm; identity when the file has no <origin>
    axis: Array  # (3,) unit; URDF's default (1, 0, 0) when absent
    origin_span: tuple[int, int] | None  # bytes of the <origin> element; None: absent
    body_start: int  # bytes: just after the <joint ...> start tag

    @property
    def moving(self) -> bool:
        """A joint with a freedom (an arm joint, or a mobile base's planar / floating)."""
        return self.type != "fixed"

    @property
    def arm_joint(self) -> bool:
        """A joint of one freedom, which an armsig joint may map to."""
        return self.type in MOVING


@dataclass(frozen=True)
class VendorURDF:
    """A vendor file: ``data`` its text as UTF-8 (byte offsets of the spans are in it),
    ``encoding`` and ``bom`` how the file wrote it (:meth:`encoded`)."""

    path: Path
    data: bytes
    name: str
    links: tuple[str, ...]
    joints: dict[str, VendorJoint]
    root: str
    encoding: str = "utf-8"
    bom: bytes = b""

    @property
    def joint_of_child(self) -> dict[str, VendorJoint]:
        return {j.child: j for j in self.joints.values()}

    def encoded(self, data: bytes) -> bytes:
        """UTF-8 ``data`` (this file's text, edited) in the file's own encoding and mark;
        a character the encoding lacks (in armsig's comments) as a character reference."""
        return self.bom + data.decode("utf-8").encode(self.encoding, "xmlcharrefreplace")


def _numbers(text: str | None, n: int, what: str) -> Array:
    if text is None:
        return np.zeros(n)
    try:
        v = np.array([float(x) for x in text.split()])
    except ValueError:
        v = np.array([])
    if v.shape != (n,) or not np.isfinite(v).all():
        raise ArmsigError(f"{what}: not {n} numbers", got=repr(text))
    return v


def read_vendor_urdf(path: str | Path) -> VendorURDF:
    """Parse ``path``; :class:`ArmsigError` in one line for a missing file, bad XML, or a
    tree that is not one robot (no single root, a joint whose links are unknown)."""
    p = Path(path)
    try:
        if p.exists() and not p.is_file():  # /dev/zero was read until memory ran out
            raise ArmsigError(
                f"the vendor URDF {p} is not a regular file",
                expected="a .urdf file", got="a device, pipe, socket or folder",
                fix="give the path of a .urdf file (xacro files: run xacro first)",
            )  # fmt: skip
        with p.open("rb") as f:
            raw = f.read(MAX_URDF_BYTES + 1)
    except OSError as exc:
        raise ArmsigError(
            f"cannot read the vendor URDF {p}", got=exc.strerror or str(exc),
            fix="give the path of a .urdf file (xacro files: run xacro first)",
        ) from exc  # fmt: skip
    if len(raw) > MAX_URDF_BYTES:
        raise ArmsigError(
            f"the vendor URDF {p} is over {MAX_URDF_BYTES // 2**20} MiB",
            expected="a robot's URDF (kilobytes; meshes are separate files)",
            fix="give the .urdf file itself, not a bundle or a mesh",
        )
    bom, encoding = _encoding(raw, p)
    try:
        text = raw[len(bom) :].decode(encoding)
    except UnicodeDecodeError as exc:
        raise ArmsigError(
            f"{p} is not {encoding} text as it declares",
            got=f"byte {exc.start + len(bom)}: {exc.reason}",
            fix="save the file in the encoding its XML declaration names",
        ) from None
    urdf = parse_vendor_urdf(text.encode("utf-8"), p)
    return replace(urdf, encoding=encoding, bom=bom)


def _encoding(raw: bytes, p: Path) -> tuple[bytes, str]:
    """The byte-order mark of ``raw`` (b"" without one) and the codec of its text: the
    mark's, else a UTF-16 document's first bytes', else the XML declaration's (read by
    expat), else UTF-8."""
    for bom, codec in _BOMS:
        if raw.startswith(bom):
            return bom, codec
    for head, codec in _WIDE:
        if raw.startswith(head):
            return b"", codec
    declared: list[str] = []
    parser = expat.ParserCreate()
    parser.XmlDeclHandler = lambda version, encoding, standalone: declared.append(encoding or "")
    try:
        parser.Parse(raw[: raw.find(b"?>") + 2] if raw.startswith(b"<?xml") else b"", True)
    except expat.ExpatError:
        pass  # a declaration expat cannot read: the whole parse says what is wrong
    name = declared[0] if declared and declared[0] else "utf-8"
    try:
        return b"", codecs.lookup(name).name
    except LookupError:
        raise ArmsigError(
            f"{p}: unknown encoding {name!r} in its XML declaration",
            expected="an encoding Python knows (UTF-8, UTF-16, ISO-8859-1, ...)",
            fix="save the file as UTF-8",
        ) from None


def parse_vendor_urdf(data: bytes, p: Path) -> VendorURDF:
    """The URDF text ``data`` (UTF-8, whatever its declaration says; read from ``p``,
    named in messages) as a :class:`VendorURDF`."""
    stack: list[str] = []
    robot: list[str] = []
    links: list[str] = []
    raw: list[dict[str, object]] = []
    parser = expat.ParserCreate("UTF-8")  # overrides the declaration: the text is UTF-8

    def start(tag: str, attrs: dict[str, str]) -> None:
        depth = len(stack)
        at = parser.CurrentByteIndex
        if depth == 0:
            robot.append(tag if tag != "robot" else attrs.get("name", ""))
        elif depth == 1 and tag == "link":
            links.append(attrs.get("name", ""))
        elif depth == 1 and tag == "joint":
            m = _START.match(data, at)
            raw.append({"name": attrs.get("name", ""), "type": attrs.get("type", ""),
                        "body": m.end() if m else at})  # fmt: skip
        elif depth == 2 and stack[1] == "joint" and raw:
            j = raw[-1]
            if tag in ("parent", "child"):
                j[tag] = attrs.get("link")
            elif tag == "axis":
                j["axis"] = attrs.get("xyz")
            elif tag == "origin":
                j["xyz"], j["rpy"], j["at"] = attrs.get("xyz"), attrs.get("rpy"), at
        stack.append(tag)

    parser.StartElementHandler = start

    def end(tag: str) -> None:
        stack.pop()
        if len(stack) == 2 and stack[1] == "joint" and tag == "origin" and raw:
            raw[-1]["end"] = parser.CurrentByteIndex  # its end tag (expat: not a comment's)

    parser.EndElementHandler = end
    try:
        parser.Parse(data, True)
    except expat.ExpatError as exc:
        raise ArmsigError(f"{p} is not XML", got=one_line(str(exc), 120)) from exc
    if robot != [robot[0]] or not raw:
        raise ArmsigError(f"{p} is not a URDF", expected="a <robot> with <joint> elements")
    joints = {}
    for j in raw:
        name = str(j["name"])
        what = f"{p}: joint {name!r}"
        if j["type"] not in KINDS or not j.get("parent") or not j.get("child"):
            raise ArmsigError(
                f"{what} is not a serial-arm joint",
                expected=f"type {', '.join(KINDS)} with a parent and a child link",
                got=f"type {j['type']!r}",
            )
        xyz = _numbers(j.get("xyz"), 3, f"{what}: origin xyz")  # type: ignore[arg-type]
        rpy = _numbers(j.get("rpy"), 3, f"{what}: origin rpy")  # type: ignore[arg-type]
        axis = _numbers(j.get("axis") or "1 0 0", 3, f"{what}: axis")  # type: ignore[arg-type]
        if not np.linalg.norm(axis) > 0:
            raise ArmsigError(f"{what}: axis is zero", expected="a direction")
        joints[name] = VendorJoint(
            name, str(j["type"]), str(j["parent"]), str(j["child"]),
            transform_from_xyz_rpy(xyz / M_PER_CM, rpy), axis / np.linalg.norm(axis),
            _span(data, j.get("at"), j.get("end")), int(j["body"]),  # type: ignore[call-overload]
        )  # fmt: skip
    children = [j.child for j in joints.values()]
    roots = [x for x in links if x not in children]
    unknown = {x for j in joints.values() for x in (j.parent, j.child)} - set(links)
    twice = sorted({c for c in children if children.count(c) > 1})
    if unknown or len(roots) != 1 or twice:
        raise ArmsigError(
            f"{p}: the links do not form one tree",
            expected="one root link, every joint's links declared, one parent per link",
            got=f"roots {roots}, undeclared {sorted(unknown)}, links with two parents {twice}",
        )
    below = {roots[0]}
    for _ in range(len(links)):  # every link reached from the root: no cycle apart from it
        below |= {j.child for j in joints.values() if j.parent in below}
    if len(below) != len(links):
        raise ArmsigError(
            f"{p}: the links do not form one tree",
            expected="every link below the root link",
            got=f"a cycle of joints through {sorted(set(links) - below)}",
        )
    return VendorURDF(p, data, robot[0], tuple(links), joints, roots[0])


def _span(data: bytes, at: object, end_at: object) -> tuple[int, int] | None:
    """Bytes of the ``<origin>`` element that starts at byte ``at`` and whose end tag
    expat found at byte ``end_at`` (a ``</origin>`` in a comment inside it is text)."""
    if at is None:
        return None
    start = int(at)  # type: ignore[call-overload]
    m = _ORIGIN.match(data, start)
    if m is None:
        raise ArmsigError("an <origin> start tag could not be delimited", got=f"byte {start}")
    if m.group(1):  # <origin .../>
        return start, m.end()
    end = _END_ORIGIN.match(data, int(end_at))  # type: ignore[call-overload]
    if end is None:
        raise ArmsigError("an <origin> element is not closed", got=f"byte {start}")
    return start, end.end()


def path_to(urdf: VendorURDF, link: str, stop: str) -> list[VendorJoint] | None:
    """The joints from link ``stop`` down to ``link`` (root first), [] if they are one,
    None if ``stop`` is not above ``link``."""
    up = urdf.joint_of_child
    out: list[VendorJoint] = []
    while link != stop:
        if link not in up:
            return None
        j = up[link]
        out.append(j)
        link = j.parent
    return list(reversed(out))


def arm_root(urdf: VendorURDF, first: str) -> str:
    """The link the arm's chain starts from, above its first joint ``first``: the root,
    or below a mobile base (the child of the last planar / floating joint on the way)."""
    link = urdf.root
    for j in path_to(urdf, urdf.joints[first].parent, urdf.root) or []:
        if j.type in FREE:
            link = j.child
    return link


def motion(j: VendorJoint, v: Array) -> Array:
    """``Rot(axis, v)`` or ``Trans(axis · v)`` of readings ``v`` (m,), rad / cm: (m, 4, 4)."""
    R = axis_frame(j.axis)
    M = trans_z(v) if j.type == "prismatic" else rot_z(v)
    out: Array = R @ M @ R.T
    return out


def axis_frame(axis: Array) -> Array:
    """A rotation (4, 4) that takes z to the unit ``axis`` (the shortest one; a half turn
    about x for −z)."""
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.dot(z, axis))
    T = np.eye(4)
    if c < -1.0 + 1e-15:
        T[:3, :3] = np.diag([1.0, -1.0, -1.0])
        return T
    k = np.cross(z, axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    T[:3, :3] = np.eye(3) + K + K @ K / (1.0 + c)  # Rodrigues, sin θ k̂ = k
    return T

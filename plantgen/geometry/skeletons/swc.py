"""SWC skeletons both ways: :func:`write_swc` and :func:`read_swc` (untrusted input).

SWC (Cannon et al. 1998, as NeuroMorpho.org standardises it) lists nodes, one a line:
``id type x y z radius parent``; ``parent`` is -1 for the root, else the id of a node
listed before; ``#`` starts a comment. Every edge from a node to its parent is a piece of
tube between the two points with the two radii.

**What plantgen writes** (one file per skeleton, a scene's plants together):

- **One root, a soma marker.** The standard allows one root, a soma (type 1, parent -1),
  from which every neurite starts. Node 1 is that marker: a point at the base of the first
  segment with its radius. Every root of the skeleton (a scene's plants, a grammar's
  ``f`` moves) starts with a node whose parent is node 1, at the root's own base, so
  neuron readers (MorphIO, NeuroM) see one tree with one stem per plant and no
  "disconnected neurite", and every segment, the first included, lies in a stem: their
  total length is the skeleton's.
- **Nodes.** A segment ends at a node; a segment that carries on its parent's axis starts
  at the parent's end node. A root, a side branch, and a segment whose start radius
  differs from its parent's end radius start at a node of their own at the same point
  (a zero-length edge carrying the start radius).
- **Types.** A node's type is the material of the segment it ends (a start node, of the
  segment it starts): the first material is 3 ("dendrite", the type neuron tools expect
  of a branching tree), the next ones 5, 6, ..., 19 (SWC's custom types; plantgen has at
  most 16 materials). The header names them (``# material 3: bark``; a backslash, a line
  break, any other control character and any character beyond ASCII is escaped, ``\\n``,
  ``\\x1b``, ``\\xe9``, and read back as it was). MorphIO refuses a
  type change between two nodes without a fork in between (unless opened with
  ``morphio.Option.unifurcated_section_change``): a grammar that changes material in
  mid-axis (``F ;(1) F``) gives such a file; plantgen's shipped models change material at
  forks only.
- **Units** are model units (SWC's convention is micrometres; plantgen scales nothing).
  **Up**: y unless ``up="z"`` turns the model so that z is up (``(x, y, z)`` ->
  ``(x, -z, y)``); the header says which, and :func:`read_swc` turns it back.
- Coordinates and radii are written with Python's shortest round-trip form, so npz ->
  SWC -> npz keeps every segment exactly: the header lists the few nodes the rules above
  cannot tell apart (``# plantgen continues:`` start nodes of segments that continue
  their parent across a radius step; ``# plantgen starts:`` start nodes that lie off
  their parent's point, where a skeleton has a gap within its tolerance;
  ``# plantgen zero-length:`` end nodes of segments of zero length).

**What plantgen reads** (any SWC file): soma nodes (type 1 with no parent or a soma
parent) are markers, not wood; a node whose parent is a soma, or that has no parent,
starts a root. A node at the very point of its parent (that is not a soma) starts a side
branch of the segment ending at its parent, with its radius as the start radius. Of the
other nodes that leave a segment's end node, the first carries the axis on
(``continues``), the others are side branches. Materials come from the header's names,
else are named by type (3 is ``bark``, others ``swc<type>``).

Every failure is one line naming the file and, where there is one, the line: not a
regular file or over ``max_skeleton_bytes``, a malformed or non-finite value, an id used
twice, a parent not listed before its child, over ``max_segments`` segments; the result
is checked by :meth:`Skeleton.validate`.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ...files import escape_text, read_input, unescape_text, write_atomically
from ...limits import LimitError, Limits, hint
from ...limits import limits as default_limits
from ...tolerances import tol
from .frames import up_rotation
from .skeleton import MAX_MATERIAL_NAMES, Skeleton, SkeletonError
from .topology import carried_on

__all__ = ["SOMA", "read_swc", "swc_lines", "swc_type_codes", "write_swc"]

#: SWC's soma type: plantgen's root marker.
SOMA = 1
#: Type of the first material, and of every node of a file without names (SWC's dendrite).
FIRST_TYPE = 3
#: Types of the further materials: SWC's custom range.
CUSTOM_TYPES = tuple(range(5, 20))
#: Node ids per header line that lists nodes.
IDS_PER_LINE = 16

_MATERIAL_LINE = re.compile(r"#\s*material\s+(\d+)\s*:\s?(.*)$")
#: The most digits of a material line's type code (an int64's), and the most blank lines
#: an SWC file may have beside its nodes and comments.
MAX_CODE_DIGITS = 18
MAX_BLANK_LINES = 100_000
_UP_LINE = re.compile(r"#\s*up\s*:\s*([yz])\b")
_LIST_LINE = re.compile(r"#\s*plantgen\s+(continues|starts|zero-length)\s*:(.*)$")


def swc_type_codes(material_names) -> list[int]:
    """The SWC type of each material: 3, then 5, 6, ... 19."""
    names = list(material_names)
    if len(names) > 1 + len(CUSTOM_TYPES):
        raise SkeletonError(f"SWC has type codes for {1 + len(CUSTOM_TYPES)} materials, the skeleton has "
                            f"{len(names)}")
    return [FIRST_TYPE, *CUSTOM_TYPES][:len(names)]


def _number(x: float) -> str:
    """Shortest text that reads back as the same float64 (``-0.0`` written as ``0``)."""
    return "0" if x == 0 else repr(float(x))


def _listing(name: str, ids: list[int]) -> list[str]:
    return [f"# plantgen {name}: " + " ".join(str(i) for i in ids[k:k + IDS_PER_LINE])
            for k in range(0, len(ids), IDS_PER_LINE)]


def swc_lines(skeleton: Skeleton, up: str = "y") -> list[str]:
    """The lines of the SWC file :func:`write_swc` writes (without line ends)."""
    n = len(skeleton)
    if n == 0:
        raise SkeletonError("an SWC file needs at least one segment")
    rot = up_rotation(up)
    start, end = skeleton.start @ rot.T, skeleton.end @ rot.T
    codes = np.array(swc_type_codes(skeleton.material_names))[skeleton.material]
    first = carried_on(skeleton.parent, skeleton.continues)
    step = first & (skeleton.r_start != skeleton.r_end[np.maximum(skeleton.parent, 0)])
    nodes: list[str] = []
    continuing, off, zero = [], [], []

    def node(code, point, radius, parent) -> int:
        nodes.append(f"{len(nodes) + 1} {code} {_number(point[0])} {_number(point[1])} {_number(point[2])} "
                     f"{_number(radius)} {parent}")
        return len(nodes)

    node(SOMA, start[0], skeleton.r_start[0], -1)
    end_id = np.zeros(n, dtype=np.int64)
    for i in range(n):
        p = int(skeleton.parent[i])
        if p >= 0 and first[i] and not step[i]:
            start_id = int(end_id[p])
        else:
            start_id = node(codes[i], start[i], skeleton.r_start[i], 1 if p < 0 else int(end_id[p]))
            if p >= 0 and skeleton.continues[i]:
                continuing.append(start_id)
            if p >= 0 and not np.array_equal(start[i], end[p]):
                off.append(start_id)
        end_id[i] = node(codes[i], end[i], skeleton.r_end[i], start_id)
        if np.array_equal(start[i], end[i]):
            zero.append(int(end_id[i]))
    header = ["# plantgen skeleton as SWC: id type x y z radius parent, one node a line",
              f"# up: {up}", "# units: model units (not micrometres); radius is a radius",
              "# node 1 (type 1, soma) marks the base of the first root; every root starts at a child of it",
              *(f"# material {c}: {escape_text(name, ascii_only=True)}"
                for c, name in zip(swc_type_codes(skeleton.material_names), skeleton.material_names, strict=True)),
              *_listing("continues", continuing), *_listing("starts", off), *_listing("zero-length", zero)]
    return header + nodes


def write_swc(skeleton: Skeleton, path: str | Path, up: str = "y") -> Path:
    """Write ``skeleton`` as SWC (see the module docstring); written to a temporary name,
    then renamed. Returns the path."""
    try:
        text = "\n".join(swc_lines(skeleton, up)) + "\n"
    except SkeletonError as exc:
        raise SkeletonError(f"{path}: {exc}") from None
    return write_atomically(path, lambda tmp: Path(tmp).write_text(text, encoding="ascii"), SkeletonError)


def read_swc(path: str | Path, limits: Limits | None = None) -> Skeleton:
    """The skeleton an SWC file describes (see the module docstring)."""
    limits = limits or default_limits
    data = read_input(path, SkeletonError, max_bytes=limits.max_skeleton_bytes, limit="skeleton_bytes",
                      what="SWC")
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError as exc:
        raise SkeletonError(f"{path}: not an SWC file (a non-ASCII byte at offset {exc.start})") from None
    header = _Header(2 * limits.max_segments + 1)
    nodes = _parse_nodes(text, path, limits, header)
    if not nodes:
        raise SkeletonError(f"{path}: an SWC file without nodes")
    skel = _segments(nodes, header)
    if len(skel) == 0:
        raise SkeletonError(f"{path}: an SWC file without segments (no node has a parent but a soma)")
    if header.up != "y":
        rot = up_rotation(header.up).T
        skel = Skeleton(skel.start @ rot.T, skel.end @ rot.T, skel.r_start, skel.r_end, skel.parent,
                        skel.continues, skel.material, skel.material_names)
    try:
        skel.validate()
    except SkeletonError as exc:
        raise SkeletonError(f"{path}: {exc}") from None
    return skel


class _Header:
    """What a file's comment lines say: up axis, material names by type, listed nodes."""

    def __init__(self, most_listed: int = 2 * default_limits.max_segments + 1) -> None:
        self.most_listed, self.listed = most_listed, 0
        self.up = "y"
        self.names: dict[int, str] = {}
        self.lists: dict[str, set[int]] = {"continues": set(), "starts": set(), "zero-length": set()}

    def read(self, comment: str, where: str) -> None:
        if m := _UP_LINE.match(comment):
            self.up = m.group(1)
        elif m := _MATERIAL_LINE.match(comment):
            if len(m.group(1)) > MAX_CODE_DIGITS:
                raise SkeletonError(f"{where}: a material type code of {len(m.group(1)):,} digits "
                                    f"(at most {MAX_CODE_DIGITS})")
            if int(m.group(1)) not in self.names and len(self.names) >= MAX_MATERIAL_NAMES:
                raise SkeletonError(f"{where}: over {MAX_MATERIAL_NAMES} material names in the header")
            self.names[int(m.group(1))] = unescape_text(m.group(2).strip())[:100] or f"swc{m.group(1)}"
        elif m := _LIST_LINE.match(comment):
            values = m.group(2).split()
            self.listed += len(values)
            if self.listed > self.most_listed:
                raise SkeletonError(f"{where}: the header lists over {self.most_listed:,} node ids, more "
                                    "than the file's nodes")
            try:
                self.lists[m.group(1)].update(int(v) for v in values)
            except ValueError:
                raise SkeletonError(f"{where}: a 'plantgen {m.group(1)}' line lists node ids (integers)") from None


def _bounded_lines(text: str, path, limits: Limits) -> list[str]:
    """The file's lines, after the checks that bound the parse, before it: at most
    ``max_segments + 1`` node lines, and at most as many comment marks as plantgen's own
    header could hold (one node id of every segment listed, 16 a line, and the rest)."""
    most_marks = limits.max_segments // 4 + 10_000
    marks = text.count("#")
    if marks > most_marks:
        raise LimitError(f"{path}: {marks:,} comment marks ('#'), over the {most_marks:,} an SWC file of at most "
                         f"{limits.max_segments:,} segments holds ({hint('segments')})")
    # counted in C before any line is split off: a file of blank lines is refused at once
    # (10 MB of them took 9 s to split and walk)
    most_lines = limits.max_segments + 1 + most_marks + MAX_BLANK_LINES
    count = text.count("\n") + 1
    if count > most_lines:
        raise LimitError(f"{path}: {count:,} lines, over the {most_lines:,} an SWC file of at most "
                         f"{limits.max_segments:,} segments holds (its nodes, its comments and "
                         f"{MAX_BLANK_LINES:,} blank lines; {hint('segments')})")
    lines = text.splitlines()
    nodes = sum(1 for line in lines if line.strip() and not line.lstrip().startswith("#"))
    limits.check("segments", nodes - 1, f"{path}: SWC segments (nodes but the first)")
    return lines


def _parse_nodes(text: str, path, limits: Limits, header: _Header) -> list[tuple]:
    """[(id, type, x, y, z, radius, parent row or -1)] in file order, ids checked."""
    lines = _bounded_lines(text, path, limits)
    rows: dict[int, int] = {}     # id -> row
    nodes = []
    kinds: set[int] = set()
    for number, line in enumerate(lines, 1):
        line, _, comment = line.partition("#")
        line = line.strip()
        where = f"{path}: line {number}"
        if not line:
            if comment:
                header.read("#" + comment, where)
            continue
        parts = line.split()
        if len(parts) != 7:
            raise SkeletonError(f"{where}: an SWC node needs 7 values (id type x y z radius parent), "
                                f"got {len(parts)}")
        try:
            node_id, kind, parent = int(parts[0]), int(parts[1]), int(parts[6])
            x, y, z, r = (float(v) for v in parts[2:6])
        except ValueError:
            raise SkeletonError(f"{where}: not an SWC node (id, type and parent are integers, "
                                "x y z radius numbers)") from None
        if not all(abs(v) <= tol.max_coordinate for v in (x, y, z, r)) or r < 0:
            raise SkeletonError(f"{where}: a coordinate or radius that is not finite, negative or "
                                f"beyond {tol.max_coordinate:g}")
        if node_id < 1 or node_id in rows:
            raise SkeletonError(f"{where}: node id {node_id} is not positive or is used twice")
        if parent != -1 and parent not in rows:
            raise SkeletonError(f"{where}: parent {parent} is not a node listed before this one")
        if kind not in kinds:
            kinds.add(kind)
            if len(kinds - {SOMA}) > MAX_MATERIAL_NAMES:
                raise SkeletonError(f"{where}: over {MAX_MATERIAL_NAMES} node types (each a material)")
        rows[node_id] = len(nodes)
        nodes.append((node_id, kind, x, y, z, r, rows[parent] if parent != -1 else -1))
        limits.check("segments", len(nodes) - 1, f"{path}: SWC segments")
    return nodes


def _material_table(kinds, header: _Header) -> tuple[dict[int, int], tuple[str, ...]]:
    """type code -> material index, and the material names: the header's, in its order,
    then the codes it does not name in order of first use."""
    used = list(dict.fromkeys(kinds))
    order = list(header.names) + [c for c in used if c not in header.names]
    default = {FIRST_TYPE: "bark"}
    names = tuple(header.names.get(c, default.get(c, f"swc{c}")) for c in order)
    return {c: i for i, c in enumerate(order)}, names or ("bark",)


def _segments(nodes: list[tuple], header: _Header) -> Skeleton:
    """One segment per edge from a node to its parent, but for soma edges and edges to
    start nodes (see the module docstring)."""
    ids = [n[0] for n in nodes]
    kinds = [n[1] for n in nodes]
    points = np.array([n[2:5] for n in nodes], dtype=np.float64)
    radius = np.array([n[5] for n in nodes], dtype=np.float64)
    parent_node = [n[6] for n in nodes]
    soma = [False] * len(nodes)
    starts = [False] * len(nodes)          # the first node of a root or a side branch
    ends_segment: dict[int, int] = {}      # node row -> the segment ending there
    carried: set[int] = set()              # segments a child already carries on
    cols = {k: [] for k in ("start", "end", "r_start", "r_end", "parent", "continues", "kind")}
    for row, p in enumerate(parent_node):
        if kinds[row] == SOMA and (p < 0 or soma[p]):
            soma[row] = True
            continue
        if p < 0 or soma[p]:
            starts[row] = True
            continue
        if not starts[p] and (ids[row] in header.lists["starts"] or (
                ids[row] not in header.lists["zero-length"] and np.array_equal(points[row], points[p]))):
            starts[row] = True             # a start node: a side branch, or listed as continuing
            continue
        if starts[p]:
            q = parent_node[p]
            seg_parent = ends_segment.get(q, -1) if q >= 0 and not soma[q] else -1
            continues = seg_parent >= 0 and ids[p] in header.lists["continues"]
        else:
            seg_parent = ends_segment[p]
            continues = seg_parent not in carried
        if continues:
            carried.add(seg_parent)
        ends_segment[row] = len(cols["end"])
        for key, value in (("start", points[p]), ("end", points[row]), ("r_start", radius[p]),
                           ("r_end", radius[row]), ("parent", seg_parent), ("continues", continues),
                           ("kind", kinds[row])):
            cols[key].append(value)
    n = len(cols["end"])
    table, names = _material_table(cols["kind"], header)
    return Skeleton(np.reshape(cols["start"], (n, 3)), np.reshape(cols["end"], (n, 3)),
                    np.array(cols["r_start"]), np.array(cols["r_end"]), np.array(cols["parent"], dtype=np.int64),
                    np.array(cols["continues"], dtype=bool),
                    np.array([table[k] for k in cols["kind"]], dtype=np.int32), names)

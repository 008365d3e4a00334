"""Point clouds (docs/formats.md, point cloud): binary little-endian PLY written with Open3D,
world frame, mm, with optional per-point intensity, line index, quality and ambient (the
room-light grey value of the camera's pixel where the point was measured, 0..1 of full
scale), and the rig it was measured on in a header comment (:mod:`insitu.formats.rig_record`).

Reading does not go through Open3D: its reader fills a short file with zeros or whatever memory
held, prints its complaints from C++ and crashes on some headers. :func:`read_ply` parses the
header itself (format, elements, counts, properties), checks the data against it (binary: the
exact byte length; ascii: the number of values) and decodes the vertices with numpy; any
mismatch is a one-line FormatError naming the file and what is wrong.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_file
from insitu.formats.bounds import BOUNDS
from insitu.formats.limits import MAX_CLOUD_BYTES, check_file, read_limited
from insitu.formats.rig_record import RigRecord, from_ply_header, ply_line

_ATTRIBUTES = ("intensity", "line", "quality", "ambient")
_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
          "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4",
          "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}
_MAX_HEADER = 65536


@dataclass(frozen=True)
class PointCloud:
    """points: (N, 3) float64 mm, world frame. attributes: name → (N,) arrays (intensity,
    line index, quality; ``ambient``: float32 0..1, the room-light grey value at the pixel
    each point was measured at, when the scan had a laser-off frame). rig: the rig it was
    measured on, None when unknown."""

    points: np.ndarray
    attributes: dict[str, np.ndarray] = field(default_factory=dict)
    rig: RigRecord | None = None

    def __len__(self) -> int:
        return len(self.points)


def write_ply(path: str | Path, cloud: PointCloud) -> None:
    """Write ``cloud`` atomically (:func:`insitu.formats.atomic.atomic_file`)."""
    path = Path(path)
    if not path.parent.is_dir():
        raise FormatError(f"{path}: folder {path.parent} does not exist")
    if path.suffix.lower() != ".ply":
        raise FormatError(f"{path}: a point cloud is written as .ply")
    import open3d as o3d  # 0.5 s to import: only when a cloud is written

    pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(np.asarray(cloud.points, np.float64)))
    for name, values in cloud.attributes.items():
        arr = np.asarray(values)
        dtype = np.int32 if np.issubdtype(arr.dtype, np.integer) else np.float32
        pcd.point[name] = o3d.core.Tensor(arr.astype(dtype).reshape(-1, 1))
    with atomic_file(path, suffix=".ply") as tmp:
        if not o3d.t.io.write_point_cloud(str(tmp), pcd, write_ascii=False, compressed=False):
            raise FormatError(f"{path}: Open3D could not write the point cloud")
        if cloud.rig is not None:           # Open3D writes no comments: one after "format"
            data = tmp.read_bytes()
            at = data.index(b"\n", data.index(b"\nformat ") + 1) + 1
            tmp.write_bytes(data[:at] + ply_line(cloud.rig) + data[at:])


def read_ply(path: str | Path) -> PointCloud:
    """Read a PLY point cloud (ascii or binary, any scalar types) with whatever of intensity,
    line, quality and ambient it holds; FormatError unless the data is exactly what the header says
    and every x, y, z is finite. Files over ``MAX_CLOUD_BYTES`` are refused unread."""
    path = Path(path)
    data = read_limited(path, MAX_CLOUD_BYTES, "point cloud", missing="no such point cloud file")
    fmt, elements, start = _header(path, data)
    names = [p[0] for p in elements.get("vertex", (0, []))[1]]
    if "vertex" not in elements or not {"x", "y", "z"} <= set(names):
        raise FormatError(f"{path}: no points: the header has no vertex element with x, y, z "
                          f"properties (vertex properties: {', '.join(names) or 'none'})")
    count, props = elements["vertex"]
    if any(len(p) != 2 for p in props):
        raise FormatError(f"{path}: a vertex property is a list (a point cloud's are numbers)")
    if count == 0:
        raise FormatError(f"{path}: no points (the header says 'element vertex 0')")
    if fmt == "ascii":
        v = _ascii_vertices(path, data, start, elements)
    else:
        v = _binary_vertices(path, data, start, elements, _FORMATS[fmt])
    pts = np.column_stack([v[c].astype(np.float64) for c in "xyz"])
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        raise FormatError(f"{path}: {int(bad.sum())} of {count} points have coordinates that are "
                          f"not finite (first: vertex {int(np.argmax(bad))}, {pts[bad][0].tolist()})")
    attrs = {n: np.ascontiguousarray(v[n]).astype(v[n].dtype.newbyteorder("="))
             for n in _ATTRIBUTES if n in v.dtype.names}
    if "ambient" in attrs:
        _check_ambient(path, attrs["ambient"])
    return PointCloud(pts, attrs, from_ply_header(path, data[:start].decode("latin-1")))


def _check_ambient(path: Path, ambient: np.ndarray) -> None:
    """FormatError naming the first vertex whose ``ambient`` is outside its range."""
    bound = BOUNDS["ambient_grey"]
    with np.errstate(invalid="ignore"):
        out = ~((ambient >= bound.lo) & (ambient <= bound.hi))
    if out.any():
        i = int(np.argmax(out))
        raise FormatError(f"{path}: vertex {i}: ambient {bound.problem(ambient[i])} "
                          f"({int(out.sum())} of {len(ambient)} vertices)")


def ply_face_count(path: str | Path) -> int:
    """How many faces the PLY file ``path`` declares in its header (0: a point cloud)."""
    path = Path(path)
    check_file(path, MAX_CLOUD_BYTES, "PLY file", missing="no such PLY file")
    with open(path, "rb") as f:
        head = f.read(_MAX_HEADER)
    return _header(path, head)[1].get("face", (0, []))[0]


def _header(path: Path, data: bytes) -> tuple[str, dict[str, tuple[int, list[tuple]]], int]:
    """(format, {element: (count, properties)} in file order, offset of the data). A property
    is (name, type) or (name, "list", count type, item type)."""
    if not data.startswith(b"ply\n") and not data.startswith(b"ply\r\n"):
        raise FormatError(f"{path}: not a PLY file (it does not start with a 'ply' line)")
    head = data[:_MAX_HEADER]
    end = next((i + len(m) for m in (b"\nend_header\n", b"\nend_header\r\n")
                if (i := head.find(m)) >= 0), -1)
    if end < 0:
        raise FormatError(f"{path}: incomplete PLY header (no 'end_header' line in its first "
                          f"{_MAX_HEADER} bytes)")
    fmt, elements = None, {}
    for n, raw in enumerate(head[:end].decode("latin-1").splitlines()[1:-1], start=2):
        words = raw.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        where = f"{path}: header line {n} {raw.strip()[:40]!r}"
        if words[0] == "format":
            if len(words) != 3 or words[1] not in _FORMATS:
                raise FormatError(f"{where}: expected 'format ascii|binary_little_endian|"
                                  "binary_big_endian 1.0'")
            fmt = words[1]
        elif words[0] == "element":
            if len(words) != 3 or not (words[2].isascii() and words[2].isdigit()):
                raise FormatError(f"{where}: expected 'element NAME COUNT' with a whole number "
                                  "COUNT >= 0")
            if words[1] in elements:
                raise FormatError(f"{where}: element {words[1]!r} is declared twice")
            elements[words[1]] = (int(words[2]), [])
        elif words[0] == "property":
            if not elements:
                raise FormatError(f"{where}: a property before any element")
            types = words[2:4] if len(words) == 5 and words[1] == "list" else words[1:2]
            if len(words) != 2 + len(types) + (len(types) == 2) or any(
                    t not in _TYPES for t in types):
                raise FormatError(f"{where}: expected 'property TYPE NAME' or 'property list "
                                  f"TYPE TYPE NAME', TYPE one of {', '.join(_TYPES)}")
            props = list(elements.values())[-1][1]
            if any(p[0] == words[-1] for p in props):
                raise FormatError(f"{where}: property {words[-1]!r} is declared twice")
            props.append((words[-1], _TYPES[types[0]]) if len(types) == 1
                         else (words[-1], "list", _TYPES[types[0]], _TYPES[types[1]]))
        else:
            raise FormatError(f"{where}: not a PLY header line")
    if fmt is None:
        raise FormatError(f"{path}: the PLY header has no 'format' line")
    return fmt, elements, end


def _row(props: list[tuple], endian: str = "") -> np.dtype:
    return np.dtype([(p[0], endian + p[1]) for p in props])


def _binary_vertices(path: Path, data: bytes, start: int, elements: dict,
                     endian: str) -> np.ndarray:
    """The vertex rows of a binary file (``endian`` "<" or ">") as a structured array, after
    the elements before it (which must have fixed-size rows); the file's length must be
    exactly what the header says."""
    offset, exact, at = start, True, None
    for name, (count, props) in elements.items():
        if any(len(p) == 4 for p in props):
            if at is None:
                raise FormatError(f"{path}: element {name!r} has list properties and comes "
                                  "before the vertex element (not readable as a point cloud)")
            exact = False                       # rows of unknown size: at least one count each
            offset += count * sum(np.dtype(endian + (p[2] if len(p) == 4 else p[1])).itemsize
                                  for p in props)
            continue
        if name == "vertex":
            at = offset
        offset += count * _row(props, endian).itemsize
    if len(data) < offset:
        raise FormatError(f"{path}: truncated: the header describes {offset - start} bytes of "
                          f"data ({elements['vertex'][0]} vertices), the file has "
                          f"{len(data) - start}")
    if exact and len(data) > offset:
        raise FormatError(f"{path}: {len(data) - offset} bytes after the data the header "
                          f"describes ({elements['vertex'][0]} vertices; is the count wrong?)")
    return np.frombuffer(data, _row(elements["vertex"][1], endian), count=elements["vertex"][0],
                         offset=at)


def _ascii_vertices(path: Path, data: bytes, start: int, elements: dict) -> np.ndarray:
    """The vertex rows of an ascii file as a structured array; the number of values must be
    what the header says."""
    tokens = data[start:].split()
    i = 0
    for name, (count, props) in elements.items():
        if name == "vertex":
            break
        if any(len(p) == 4 for p in props):
            raise FormatError(f"{path}: element {name!r} has list properties and comes before "
                              "the vertex element (not readable as a point cloud)")
        i += count * len(props)
    count, props = elements["vertex"]
    need = count * len(props)
    if len(tokens) < i + need:
        raise FormatError(f"{path}: truncated: the header describes {count} vertices of "
                          f"{len(props)} values, the file holds {max(len(tokens) - i, 0)} values")
    fixed = all(len(p) == 2 for _, ps in elements.values() for p in ps)
    rest = sum(c * len(ps) for _, (c, ps) in list(elements.items())) if fixed else None
    if rest is not None and len(tokens) > rest:
        raise FormatError(f"{path}: {len(tokens) - rest} values after the data the header "
                          f"describes ({count} vertices; is the count wrong?)")
    try:
        table = np.array(tokens[i:i + need]).astype(np.float64).reshape(count, len(props))
    except ValueError:
        raise FormatError(f"{path}: the vertex data holds values that are not numbers") from None
    out = np.empty(count, _row(props))
    with np.errstate(invalid="ignore", over="ignore"):     # nan in an integer column
        for k, (name, _) in enumerate(props):
            out[name] = table[:, k]
    return out

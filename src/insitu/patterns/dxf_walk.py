"""What a CAD program shows of a DXF's model space: the entities to draw, each with the layer
and linetype it is drawn with.

Blocks (INSERT), dimensions, leaders and multi-lines are exploded recursively; an entity on
layer "0" inside a block takes the layer of the INSERT that places it, a BYBLOCK linetype
the INSERT's. Layers that are off, frozen or not plotted hide what lies on them (an INSERT
on such a layer hides its whole block). An entity ezdxf cannot explode is skipped with a note
naming its type and handle. Units: only a ``$INSUNITS`` the file's own HEADER holds counts
(ezdxf fills a default header into a file without one).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

_EXPLODED = ("INSERT", "DIMENSION", "ARC_DIMENSION", "LARGE_RADIAL_DIMENSION", "LEADER",
             "MLEADER", "MULTILEADER", "MLINE")
MESHES = ("MESH", "3DSOLID", "BODY", "REGION", "SURFACE", "EXTRUDEDSURFACE", "LOFTEDSURFACE",
          "REVOLVEDSURFACE", "SWEPTSURFACE", "PLANESURFACE", "POLYFACE", "POLYMESH")


def header_has(path: Path, name: bytes) -> bool:
    """True when the file's own HEADER section holds the variable ``name`` (e.g.
    b"$INSUNITS"), ASCII or binary DXF."""
    raw = path.read_bytes()
    start = raw.find(b"HEADER")
    if start < 0:
        return False
    end = raw.find(b"ENDSEC", start)
    return name in raw[start:end if end > 0 else len(raw)]


def hidden_layers(doc) -> dict[str, str]:
    """Layer name (lower case) → why it is hidden: "off", "frozen" or "not plotted"."""
    out = {}
    for layer in doc.layers:
        why = ("frozen" if layer.is_frozen() else "off" if layer.is_off()
               else "not plotted" if not layer.dxf.get("plot", 1) else None)
        if why:
            out[layer.dxf.name.lower()] = why
    return out


def kind_of(e) -> str:
    """The entity's type; a POLYLINE that is a polyface or polygon mesh as POLYFACE /
    POLYMESH."""
    kind = e.dxftype()
    if kind == "POLYLINE":
        if e.is_poly_face_mesh:
            return "POLYFACE"
        if e.is_polygon_mesh:
            return "POLYMESH"
    return kind


def name_of(e) -> str:
    """"TYPE #handle" of an entity, for notes."""
    return f"{e.dxftype()} #{e.dxf.get('handle', '?')}"


def visible_entities(doc, hidden: dict[str, str], skipped: list[str],
                     hidden_count: dict[str, int]) -> Iterator[tuple[object, str, str]]:
    """(entity, layer, linetype name) of every model-space entity a CAD program draws, blocks
    and dimensions exploded. ``skipped`` gets one "TYPE #handle: why" per entity that could
    not be exploded; ``hidden_count`` counts, per hidden layer, the entities it hides."""

    def walk(entities, parent_layer: str | None, parent_ltype: str, depth: int):
        for e in entities:
            layer = e.dxf.get("layer", "0") or "0"
            if layer == "0" and parent_layer is not None:
                layer = parent_layer
            ltype = e.dxf.get("linetype", "BYLAYER") or "BYLAYER"
            if ltype.upper() == "BYBLOCK":
                ltype = parent_ltype
            if layer.lower() in hidden:
                hidden_count[layer] = hidden_count.get(layer, 0) + 1
                continue
            if e.dxf.get("invisible", 0):
                continue
            kind = e.dxftype()
            if kind in _EXPLODED and depth < 32:
                try:
                    parts = list(e.multi_insert()) if kind == "INSERT" and e.mcount > 1 \
                        else None
                    if parts is not None:
                        yield from walk(parts, parent_layer, parent_ltype, depth + 1)
                        continue
                    children = list(e.virtual_entities())
                except Exception as err:  # noqa: BLE001 — a malformed entity, named
                    why = " ".join(str(err).split())[:60] or "malformed"
                    skipped.append(f"{name_of(e)}: {why}")
                    continue
                if kind == "INSERT":
                    yield from walk(e.attribs, layer, ltype, depth + 1)
                yield from walk(children, layer, ltype, depth + 1)
                continue
            yield e, layer, ltype

    yield from walk(doc.modelspace(), None, "CONTINUOUS", 0)


def line_pattern(doc, e, layer: str, ltype: str) -> tuple[float, ...] | None:
    """The dash pattern (dash, gap, dash, gap, … in drawing units, scaled by ``$LTSCALE`` and
    the entity's own ltscale) of an entity's linetype, None for a continuous line."""
    if ltype.upper() == "BYLAYER":
        entry = doc.layers.get(layer) if layer in doc.layers else None
        ltype = entry.dxf.get("linetype", "CONTINUOUS") if entry is not None else "CONTINUOUS"
    if ltype.upper() in ("CONTINUOUS", "BYLAYER", "BYBLOCK") or ltype not in doc.linetypes:
        return None
    try:
        pattern = [abs(float(x)) for x in doc.linetypes.get(ltype).simplified_line_pattern()]
    except Exception:  # noqa: BLE001 — a complex linetype ezdxf cannot simplify: continuous
        return None
    if len(pattern) % 2:
        pattern.append(0.0)
    if len(pattern) < 2 or sum(pattern[1::2]) <= 0:
        return None
    scale = float(doc.header.get("$LTSCALE", 1.0) or 1.0) * float(e.dxf.get("ltscale", 1.0)
                                                                  or 1.0)
    return tuple(x * scale for x in pattern) if scale > 0 else None

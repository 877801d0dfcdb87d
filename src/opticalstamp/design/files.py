"""Design files: TOML presets and files read into a design of their ``kind``.

Invalid input raises :class:`DesignError` naming every offending field and its rule.
"""

from __future__ import annotations

import difflib
import re
import tomllib
import typing
from importlib import resources
from pathlib import Path

from pydantic import BaseModel, ValidationError

from .model import MAX_DESIGN_FILE_BYTES, Design, DesignError
from .rodlens import KIND as RODLENS
from .rodlens import RodLensDesign

STAMP = "stamp"
KINDS = (STAMP, RODLENS)
#: Any design opticalstamp can analyse.
AnyDesign = Design | RodLensDesign


def slab_where(loc: tuple, data: object = None) -> str:
    """Where the user finds the slab of the field ``loc`` (pydantic's path, its slab index
    0-based, sensor first), "" for a field of no slab: the design file's ``[[slabs]]``
    tables are counted from the sensor, the paper counts slabs and mask layers from the
    object side (slab 1 is the slab under layer 1). ``data``: the design as read, for the
    number of slabs and which of them carry a mask."""
    slabs = data.get("slabs") if isinstance(data, dict) else None
    if len(loc) < 2 or loc[0] != "slabs" or not isinstance(loc[1], int):
        return ""
    if not isinstance(slabs, list | tuple) or not 0 <= loc[1] < len(slabs):
        return ""
    i, n = loc[1], len(slabs)
    side = f"slab {n - i} from the object side"
    if len(loc) > 2 and loc[2] == "mask_top":
        layer = sum(isinstance(sl, dict) and sl.get("mask_top") is not None for sl in slabs[i:])
        side += f", its mask layer {layer}" if layer else ""
    return f"[[slabs]] table {i + 1} of {n} counted from the sensor ({side})"


def _model_at(model: type[BaseModel], loc: tuple) -> type[BaseModel] | None:
    """The model whose field the path ``loc`` (pydantic's, list indices included) names
    last, or None where the path leaves the models."""
    for part in loc:
        if isinstance(part, int):
            continue
        field = model.model_fields.get(part)
        if field is None:
            return None
        inner = [field.annotation]
        found = None
        while inner and found is None:
            t = inner.pop()
            if isinstance(t, type) and issubclass(t, BaseModel):
                found = t
            else:
                inner.extend(typing.get_args(t))
        if found is None:
            return None
        model = found
    return model


def _did_you_mean(model: type[BaseModel], loc: tuple) -> str:
    """ ", did you mean 'x'?" for an unknown key ``loc[-1]`` close to a field of its
    table, else ""."""
    parent = _model_at(model, loc[:-1])
    if parent is None or not loc or not isinstance(loc[-1], str):
        return ""
    close = difflib.get_close_matches(loc[-1], list(parent.model_fields), n=1, cutoff=0.75)
    return f"; did you mean {close[0]!r}?" if close else ""


def format_validation_error(
    err: ValidationError, source: str, data: object = None, model: type[BaseModel] = Design
) -> str:
    """One line per offending field: its path (a slab's field after where the user finds
    it, see :func:`slab_where`; ``data`` is the design as read), the rule, the value given
    (an unknown key: the field of ``model``'s table it is closest to, where one is)."""
    lines = [f"invalid design {source}:"]
    for e in err.errors():
        loc, msg = tuple(e["loc"]), e["msg"].removeprefix("Value error, ")
        head = re.match(r"(slabs\.(\d+)(?:\.\w+)*): ", msg) if not loc else None
        if head:  # a rule of the whole design that names a slab's field first
            loc = tuple(int(p) if p.isdigit() else p for p in head[1].split("."))
            msg = msg[head.end() :]
        where = slab_where(loc, data)
        if e["type"] == "extra_forbidden":
            msg = "unknown key (not part of the design format)" + _did_you_mean(model, loc)
        loc = (f"{where} — " if where else "") + (".".join(map(str, loc)) or "(top level)")
        got = e.get("input")
        skip = isinstance(got, dict | list) or e["type"] == "missing" or "(got" in msg
        shown = "" if skip else f" (got {got!r})"
        lines.append(f"  {loc}: {msg}{shown}")
    return "\n".join(lines)


def design_from_dict(data: dict, source: str = "<dict>") -> AnyDesign:
    """Validate a mapping (as read from TOML) into a design of its ``kind``.

    ``kind`` absent or ``"stamp"``: a :class:`Design` (the optical stamp);
    ``"rod-lens-array"``: a :class:`RodLensDesign`.
    """
    kind = data.get("kind", STAMP) if isinstance(data, dict) else STAMP
    if kind not in KINDS:
        raise DesignError(
            f"invalid design {source}:\n  kind: must be one of {', '.join(KINDS)} (got {kind!r})"
        )
    model = RodLensDesign if kind == RODLENS else Design
    try:  # a stamp's model has no ``kind`` field
        return model.model_validate(
            data if kind == RODLENS else {k: v for k, v in data.items() if k != "kind"}
        )
    except ValidationError as err:
        raise DesignError(format_validation_error(err, source, data, model)) from None
    except RecursionError:
        raise DesignError(f"invalid design {source}: nested too deeply") from None


def preset_text(name: str) -> str:
    """The TOML text of the built-in preset ``name`` (one of :func:`preset_names`)."""
    return (resources.files("opticalstamp.design") / "presets" / f"{name}.toml").read_text()


def preset_names() -> list[str]:
    files = resources.files("opticalstamp.design") / "presets"
    return sorted(p.name.removesuffix(".toml") for p in files.iterdir() if p.name.endswith(".toml"))


def load_design(spec: str | Path) -> AnyDesign:
    """Load a built-in preset by name or a design TOML file by path.

    A UTF-8 byte-order mark is accepted; files over MAX_DESIGN_FILE_BYTES and TOML nested
    too deeply for the parser are refused with a :class:`DesignError`.
    """
    spec_s = str(spec)
    if spec_s in preset_names():
        text = preset_text(spec_s)
        source = f"preset {spec_s!r}"
    else:
        path = Path(spec_s)
        if not path.is_file():
            raise DesignError(
                f"design {spec_s!r} is neither a preset ({', '.join(preset_names())}) "
                "nor a readable file"
            )
        try:
            if path.stat().st_size > MAX_DESIGN_FILE_BYTES:
                raise DesignError(
                    f"design file {spec_s}: larger than {MAX_DESIGN_FILE_BYTES >> 10} KiB; "
                    "a design is a short TOML file"
                )
            text = path.read_text(encoding="utf-8-sig")
        except (OSError, UnicodeDecodeError) as err:
            raise DesignError(f"cannot read design file {spec_s}: {err}") from None
        source = f"file {spec_s}"
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise DesignError(f"malformed TOML in {source}: {err}") from None
    except RecursionError:
        raise DesignError(
            f"malformed TOML in {source}: tables or arrays nested too deeply"
        ) from None
    return design_from_dict(data, source)


def design_toml(design: AnyDesign, comments: tuple[str, ...] = ()) -> str:
    """The design as a design file's TOML text (read back by :func:`load_design` into the
    same design, the same fingerprint), with ``comments`` as ``#`` lines at the top (the
    provenance of a generated file; TOML comments are not part of the design)."""
    import tomli_w

    data = design.model_dump(mode="json", exclude_none=True)
    if isinstance(design, RodLensDesign):
        data = {"kind": RODLENS} | {k: v for k, v in data.items() if k != "kind"}
    head = "".join(f"# {line}\n" for c in comments for line in c.splitlines())
    return head + tomli_w.dumps(data)

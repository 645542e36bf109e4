"""The configuration reference, generated from the key declarations of :mod:`kite_env.config`.

Writes ``configs/default.yaml`` (every section and key with its default and a comment: meaning [unit], the values
allowed) and ``docs/configuration.md`` (a table per section: key, unit, default, meaning, allowed values; then the
longer notes). Each key's documentation and checks are its :func:`kite_env.config.key` declaration; the sections that
declare their fields elsewhere (``wind``, ``trajectory``) are read from their source: a field's comments, and the
messages of their ``validate()``.

    python -m kite_env.config_reference --write   # regenerate both files after adding or changing a key
    python -m kite_env.config_reference --check   # exit 1 when the committed files are not what it writes
"""

from __future__ import annotations

import argparse
import inspect
import math
import re
import sys
from collections.abc import Iterator
from dataclasses import MISSING, Field, dataclass, fields
from pathlib import Path
from typing import Any

import yaml

from kite_env.config import MODEL_SECTIONS, PRESETS, RETIRED, RETIRED_NOW, Config, allowed_values

ROOT = Path(__file__).resolve().parents[1]
#: the generated files, relative to the repository root
DEFAULT_YAML = Path("configs") / "default.yaml"
REFERENCE_MD = Path("docs") / "configuration.md"
COMMAND = "python -m kite_env.config_reference --write"


@dataclass(frozen=True)
class KeyDoc:
    """One key as documented: name, default, meaning, unit, allowed values, longer note."""

    name: str
    default: Any
    doc: str
    unit: str
    allowed: str
    note: str
    choices: tuple[Any, ...] | None


def _section_classes() -> list[tuple[str, type]]:
    return [(f.name, f.default_factory) for f in fields(Config)  # type: ignore[misc]
            if f.default_factory is not MISSING]


def _summary(cls: type) -> str:
    doc = cls.__doc__ or ""
    if doc.startswith(f"{cls.__name__}("):  # the docstring dataclass() makes up: its module's first line then
        doc = (sys.modules[cls.__module__].__doc__ or "").split("\n")[0]
    return " ".join(doc.split())


def _source_comments(cls: type) -> dict[str, tuple[str, str]]:
    """``{field: (trailing comment, comment lines above it)}`` of a dataclass declared with plain comments."""
    lines, _ = inspect.getsourcelines(cls)
    out: dict[str, tuple[str, str]] = {}
    above: list[str] = []
    for line in lines[1:]:
        stripped = line.strip()
        if stripped.startswith("#"):
            above.append(stripped.lstrip("#").strip())
            continue
        m = re.match(r"^\s+(\w+):\s*[^=]+=.*?(?:\s\s#\s*(.*))?$", line.rstrip())
        if m:
            out[m.group(1)] = ((m.group(2) or "").strip(), " ".join(above))
        above = []
    return out


def _validate_messages(cls: type, section: str) -> dict[str, list[str]]:
    """What ``cls.validate`` requires of each field, from its error messages (``section.field must ..., got``)."""
    validate = getattr(cls, "validate", None)
    if validate is None:
        return {}
    src = inspect.getsource(validate)
    module = sys.modules[cls.__module__]

    def join(m: re.Match[str]) -> str:
        return ", ".join(getattr(module, m.group(1)))

    out: dict[str, list[str]] = {}
    for m in re.finditer(rf"{section}\.(\w+) must (.*?), got", src):
        if "{" in m.group(1):
            continue
        text = re.sub(r"\{', '\.join\((\w+)\)\}", join, m.group(2))
        if text != "be finite":
            out.setdefault(m.group(1), []).append(text.removeprefix("be ").removeprefix("lie in "))
    return out


def _split_unit(comment: str) -> tuple[str, str]:
    m = re.search(r"\s*\[([^\]]+)\]\s*$", comment)
    return (comment[:m.start()].strip(), m.group(1)) if m else (comment, "")


def section_keys(name: str, cls: type) -> Iterator[KeyDoc]:
    """The keys of the section ``name`` (class ``cls``) as documented."""
    comments = _source_comments(cls)
    required = _validate_messages(cls, name)
    for f in fields(cls):
        default = _default(f)
        if "doc" in f.metadata:
            meta = f.metadata
            yield KeyDoc(f.name, default, meta["doc"], meta["unit"], allowed_values(meta), meta["note"],
                         meta["choices"])
            continue
        trailing, above = comments.get(f.name, ("", ""))
        doc, unit = _split_unit(trailing)
        note = ""
        if not doc:
            doc, unit2 = _split_unit(above)
            unit = unit or unit2
        else:
            note = above
        yield KeyDoc(f.name, default, doc, unit, "; ".join(required.get(f.name, [])), note, None)


def _default(f: Field[Any]) -> Any:
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:
        return f.default_factory()
    raise ValueError(f"field {f.name} has no default")


def yaml_value(value: Any) -> str:
    """``value`` as a YAML scalar that reads back as itself (floats in their shortest form that does)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isinf(value):
            return ".inf" if value > 0 else "-.inf"
        candidates = []
        for form in (repr(value), f"{value:.6g}", f"{value:.12g}", f"{value:.6e}", f"{value:.1e}", f"{value:.2e}"):
            text = form
            if "e" in form:  # YAML 1.1 reads a float with a dot in the mantissa and a signed exponent
                mant, exp = form.split("e")
                mant = mant.rstrip("0") if "." in mant else mant + "."
                text = f"{mant}0e{int(exp):+d}" if mant.endswith(".") else f"{mant}e{int(exp):+d}"
            elif "." not in form:
                text = form + ".0"
            parsed = yaml.safe_load(text)
            if isinstance(parsed, float) and parsed == value:
                candidates.append(text)
        plain = repr(value)  # a plain decimal where it is short (15000.0, not 1.5e+4)
        if "e" not in plain and len(plain) <= 10:
            candidates = [plain]
        text = min(candidates, key=len) if candidates else yaml.safe_dump(value).split("\n")[0]
    elif isinstance(value, str):
        reads_back = bool(value) and yaml.safe_load(value) == value
        text = value if reads_back and ":" not in value and "#" not in value else yaml.safe_dump(value).split("\n")[0]
    else:
        text = yaml.safe_dump(value).split("\n")[0]
    if yaml.safe_load(text) != value and not (isinstance(value, float) and math.isnan(value)):
        raise ValueError(f"{value!r} does not read back from {text!r}")
    return text


def _comment(k: KeyDoc) -> str:
    text = k.doc + (f" [{k.unit}]" if k.unit else "")
    shown = k.choices is not None and all(str(c) in k.doc for c in k.choices)
    if k.allowed and not shown:
        text += f"; {k.allowed}"
    return text


def _first_sentence(text: str) -> str:
    m = re.match(r"(.+?(?<!Sect)(?<!Eq)(?<!Fig)\.)(\s+[A-Z]|$)", text)
    return (m.group(1) if m else text).rstrip(".")


def render_yaml() -> str:
    """The text of ``configs/default.yaml``."""
    out = ["# kite_env default configuration: every section and key with its default; the comment says what it is",
           "# [unit] and the values it takes. Generated from the key declarations of kite_env/config.py by",
           f"# `{COMMAND}`: do not edit here. docs/configuration.md explains each key; configs/paper.yaml",
           "# holds the paper's model (PRESETS['paper'])."]
    for name, cls in _section_classes():
        summary = _summary(cls)
        out.append(f"{name}:" + (f"{'':{26 - len(name)}}# {_first_sentence(summary)}" if summary else ""))
        for k in section_keys(name, cls):
            entry = f"  {k.name}: {yaml_value(k.default)}"
            out.append(f"{entry:<26} # {_comment(k)}".rstrip())
    return "\n".join(out) + "\n"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def render_markdown() -> str:
    """The text of ``docs/configuration.md``."""
    out = ["# Configuration reference", "",
           f"Generated from the key declarations of `kite_env/config.py` by `{COMMAND}`: do not edit here (a test "
           "fails when this file is not what the command writes). Every key, its unit, its default, what it means "
           "and the values it takes; the longer notes follow each table.", "",
           "A configuration is built in layers, each on top of the last: the defaults below, a YAML file "
           "(`configs/default.yaml` lists them all; `configs/paper.yaml` is the paper's model), then "
           "`section.key=value` overrides (`--set` on the command line, `overrides=[...]` for the environments). "
           "An unknown key, a value of the wrong type or one outside the allowed values raises `ConfigError` naming "
           "the key; so do values that contradict each other (checked in `kite_env.config._validate`). Every number "
           "must be finite (`.inf` only where the table allows it).", "",
           "Each key is declared once, with `kite_env.config.key(default, doc, unit, choices=..., lo=..., hi=..., "
           "note=...)`: this page and `configs/default.yaml` are written from those declarations. The `wind` and "
           "`trajectory` sections are declared in their own modules (`WindConfig`, `TrajectoryConfig`, which check "
           "themselves): their rows are read from the fields' comments and the messages of their `validate()`.", "",
           f"The sections {', '.join(f'`{s}`' for s in MODEL_SECTIONS)} are the model: an artefact made with one "
           "(a reduced-order wing, a start table, an agent) records their keys (`kite_env.config.fingerprint`) and "
           "refuses another. The others (solver, run, wind, figure, task) are not.", ""]
    paper = PRESETS["paper"]
    for name, cls in _section_classes():
        out += [f"## `{name}`", ""]
        summary = _summary(cls)
        if summary:
            out += [summary + (" Part of the model." if name in MODEL_SECTIONS else ""), ""]
        out += ["| key | unit | default | meaning | allowed |", "|---|---|---|---|---|"]
        keys = list(section_keys(name, cls))
        for k in keys:
            default = f"`{yaml_value(k.default)}`" if yaml_value(k.default) != "''" else '`""`'
            out.append(f"| `{k.name}` | {_cell(k.unit)} | {default} | {_cell(k.doc)} | {_cell(k.allowed)} |")
        if name in paper:
            sets = ", ".join(f"`{key}: {yaml_value(v)}`" for key, v in paper[name].items())
            out += ["", f"The paper's model (preset `paper`, `configs/paper.yaml`) sets {sets}."]
        notes = [k for k in keys if k.note]
        if notes:
            out += ["", "Notes:", ""]
            out += [f"- `{name}.{k.name}`: {k.note}" for k in notes]
        out.append("")
    out += ["## Retired keys", "",
            "Keys that only chose a former default are retired with it: a configuration that gives one is refused "
            "(`ConfigError`). Each has one value now (`kite_env.config.RETIRED`); those of the model's sections "
            "stay in a model's record at that value, so an artefact made before keeps its fingerprint and one made "
            "at another value is refused.", "",
            "| key | always | what every model does |", "|---|---|---|"]
    out += [f"| `{k}` | `{yaml_value(v)}` | {_cell(RETIRED_NOW[k])} |" for k, v in RETIRED.items()]
    out.append("")
    return "\n".join(out)


#: the generated files and their renderers
GENERATED = {DEFAULT_YAML: render_yaml, REFERENCE_MD: render_markdown}


def stale(root: Path = ROOT) -> list[Path]:
    """The generated files under ``root`` whose text is not what the generator writes now."""
    return [p for p, render in GENERATED.items()
            if not (root / p).is_file() or (root / p).read_text() != render()]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m kite_env.config_reference", description=__doc__.split("\n")[0])
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", action="store_true", help="write configs/default.yaml and docs/configuration.md")
    g.add_argument("--check", action="store_true", help="exit 1 if a generated file is out of date")
    p.add_argument("--root", type=Path, default=ROOT, help="repository root (default: this checkout)")
    args = p.parse_args(argv)
    if args.write:
        for path, render in GENERATED.items():
            (args.root / path).write_text(render())
            print(f"wrote {args.root / path}")
        return 0
    old = stale(args.root)
    for path in old:
        print(f"{path} is out of date: run {COMMAND}", file=sys.stderr)
    return 1 if old else 0


if __name__ == "__main__":
    sys.exit(main())

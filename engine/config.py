"""TOML loading and validation with errors written for people.

Every problem found in a file is collected into one :class:`ConfigError`: the file, the TOML key
path, the offending value, what was expected, a "did you mean" for unknown names, and a line number
where one can be found (tomllib keeps none, so :func:`locate_line` scans the text for the key).
"""

from __future__ import annotations

import difflib
import os
import re
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, field_validator

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on 3.10 only
    import tomli as tomllib


class ConfigModel(BaseModel):
    """Base of every config a modder writes: unknown keys are errors, strings never pass as numbers, and
    TOML's ``nan`` / ``inf`` never pass as a float (they would poison a simulation without an error), nor do
    subnormal numbers (0 < |x| < 2.2e-308: a bound like ``gt=0`` lets 5e-324 through, whose reciprocal is
    infinite)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)

    @field_validator("*", mode="after")
    @classmethod
    def _no_subnormal(cls, value: Any) -> Any:
        tiny = _subnormal(value)
        if tiny is not None:
            raise ValueError(f"too small to compute with (a subnormal number): expected 0 or a "
                             f"magnitude of at least {sys.float_info.min:.3g}")
        return value


def _subnormal(value: Any) -> float | None:
    """The first subnormal float in ``value`` (a number, or lists and tuples of them), else None."""
    if isinstance(value, float):
        return value if value != 0.0 and abs(value) < sys.float_info.min else None
    if isinstance(value, (list, tuple)):
        for item in value:
            tiny = _subnormal(item)
            if tiny is not None:
                return tiny
    return None


def _as_tuple(v: list[float]) -> tuple[float, ...]:
    return tuple(float(x) for x in v)


COORD_LIMIT = 1.0e6  # |component| of any vector a modder writes: metres, m/s, degrees, fractions alike
Coord = Annotated[float, Field(ge=-COORD_LIMIT, le=COORD_LIMIT)]
Vec2 = Annotated[list[Coord], Field(min_length=2, max_length=2), AfterValidator(_as_tuple)]
Vec3 = Annotated[list[Coord], Field(min_length=3, max_length=3), AfterValidator(_as_tuple)]
Vec4 = Annotated[list[Coord], Field(min_length=4, max_length=4), AfterValidator(_as_tuple)]
Color3 = Annotated[list[Annotated[float, Field(ge=0.0, le=64.0)]], Field(min_length=3, max_length=3),
                   AfterValidator(_as_tuple)]


@dataclass(frozen=True)
class Problem:
    """One thing wrong in one file."""

    file: str
    key: str
    message: str
    value: Any = None
    suggestion: str | None = None
    line: int | None = None

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}" if self.line else self.file
        text = f"{where}: {self.key or '<file>'}: {self.message}"
        if self.value is not None:
            text += f" (got {_short(self.value)})"
        if self.suggestion:
            text += f"; did you mean '{self.suggestion}'?"
        return text


class CrossFieldError(ValueError):
    """A model validator's complaint about keys that are each valid alone but not together.

    Raise it from a ``model_validator`` instead of a bare ``ValueError``: the problem is reported at the first of
    ``keys`` that the file sets (its line, or the preset's that set it), and it is still reported when other
    keys of the same file have errors of their own, as long as none of ``keys`` is among them
    (:func:`model_problems`), so a modder sees every problem in one pass.
    """

    def __init__(self, keys: str | Sequence[str], message: str) -> None:
        self.keys = (keys,) if isinstance(keys, str) else tuple(keys)
        if not self.keys:
            raise TypeError("CrossFieldError needs at least one key")
        super().__init__(message)


class ConfigError(Exception):
    """All problems found while loading one or more config files."""

    def __init__(self, problems: Sequence[Problem]) -> None:
        self.problems = list(problems)
        super().__init__(self._text())

    def _text(self) -> str:
        n = len(self.problems)
        head = f"{n} problem{'s' if n != 1 else ''} in config:"
        return "\n".join([head, *("  " + str(p) for p in self.problems)])


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def suggest(name: str, choices: Iterable[str]) -> str | None:
    """The closest of ``choices`` to ``name``, if any is close enough."""
    found = difflib.get_close_matches(str(name), sorted(choices), n=1, cutoff=0.6)
    return found[0] if found else None


def format_key(parts: Sequence[Any]) -> str:
    """('entities', 0, 'components', 'X') -> 'entities[0].components.X'."""
    out = ""
    for part in parts:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


# --------------------------------------------------------------------------- files
def read_toml(path: Path) -> tuple[dict, str]:
    """Parse a TOML file; syntax errors and unreadable files become :class:`ConfigError`."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError([Problem(str(path), "", "file not found")]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError([Problem(str(path), "", f"cannot read file: {exc}")]) from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        match = re.search(r"line (\d+)", str(exc))
        line = int(match.group(1)) if match else None
        raise ConfigError([Problem(str(path), "", f"TOML syntax error: {exc}", line=line)]) from None
    except RecursionError:  # arrays or inline tables nested hundreds deep: the parser recurses per level
        raise ConfigError([Problem(str(path), "", "arrays or tables nested too deeply to read (hundreds of "
                                                  "levels)")]) from None


_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_ASSIGN = re.compile(r"^\s*([A-Za-z0-9_\-\.\"' ]+?)\s*=")


def _split_dotted(key: str) -> list[str]:
    return [p.strip().strip("\"'") for p in key.split(".")]


def locate_line(text: str, key_path: Sequence[Any], exact: bool = False) -> int | None:
    """Best-effort 1-based line of ``key_path`` in TOML ``text``; falls back to the nearest parent (``exact``:
    ``None`` when the key itself is not written there)."""
    target = format_key(key_path)
    found: dict[str, int] = {}
    table: list[Any] = []
    array_counts: dict[str, int] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        header = _HEADER.match(line)
        if header:
            parts: list[Any] = _split_dotted(header.group(2))
            if header.group(1) == "[[":
                base = format_key(parts)
                index = array_counts.get(base, -1) + 1
                array_counts[base] = index
                parts = parts + [index]
            table = _resolve_arrays(parts, array_counts)
            found.setdefault(format_key(table), lineno)
            continue
        assign = _ASSIGN.match(line)
        if assign:
            found.setdefault(format_key(table + _split_dotted(assign.group(1))), lineno)
    if exact:
        return found.get(target)
    parts = list(key_path)
    while parts:
        key = format_key(parts)
        if key in found:
            return found[key]
        parts.pop()
    return None if target else 1


def _resolve_arrays(parts: list[Any], counts: dict[str, int]) -> list[Any]:
    """Insert the current index after every array-of-tables prefix (``entities`` -> ``entities[2]``)."""
    out: list[Any] = []
    for i, part in enumerate(parts):
        out.append(part)
        if isinstance(part, str) and i + 1 < len(parts) and not isinstance(parts[i + 1], int):
            prefix = format_key([p for p in out if not isinstance(p, int)])
            if prefix in counts:
                out.append(counts[prefix])
    return out


# ---------------------------------------------------------------------- validation
def _cross_field_keys(err: dict) -> tuple[str, ...] | None:
    error = (err.get("ctx") or {}).get("error")
    return error.keys if isinstance(error, CrossFieldError) else None


def _hidden_cross_field_errors(errors: list[dict], model: type[BaseModel], data: Any,
                               context: dict | None) -> list[dict]:
    """The model's own cross-field errors that its field errors kept pydantic from checking.

    pydantic runs a model's ``mode="after"`` validators only once every field is valid. Validated again without
    the keys that had errors (their defaults stand in), the model's :class:`CrossFieldError` s whose keys are all
    outside those are real problems of the file too.
    """
    if not isinstance(data, dict) or not errors or any(not err["loc"] for err in errors):
        return []
    bad = {err["loc"][0] for err in errors}
    try:
        model.model_validate({k: v for k, v in data.items() if k not in bad}, context=context)
    except ValidationError as exc:
        return [err for err in exc.errors(include_url=False)
                if not err["loc"] and (keys := _cross_field_keys(err)) and not bad.intersection(keys)]
    except Exception:  # noqa: BLE001 - a validator tripping over a stand-in default reports nothing extra
        return []
    return []


def model_problems(exc: ValidationError, model: type[BaseModel], file: str, prefix: Sequence[Any],
                   text: str | None = None, text_prefix: Sequence[Any] | None = None, data: Any = None,
                   context: dict | None = None) -> list[Problem]:
    """Translate a pydantic error into problems whose key paths are TOML key paths.

    With the ``data`` (and ``context``) that failed, the model's cross-field problems hidden behind its field
    errors are reported too (:func:`_hidden_cross_field_errors`).
    """
    problems = []
    errors = exc.errors(include_url=False)
    errors += _hidden_cross_field_errors(errors, model, data, context)
    text_base = list(text_prefix if text_prefix is not None else prefix)
    for err in errors:
        loc = [p for p in err["loc"] if not (isinstance(p, str) and p.startswith("function-"))]
        keys = _cross_field_keys(err)
        if keys:  # reported at the first of its keys the file writes (else the first)
            written = [k for k in keys if text and locate_line(text, text_base + loc + [k], exact=True)]
            loc = loc + [(written or keys)[0]]
        suggestion = None
        message = err["msg"]
        if err["type"] == "extra_forbidden":
            fields = _fields_at(model, loc[:-1])
            suggestion = suggest(str(loc[-1]), fields)
            message = f"unknown key '{loc[-1]}'" + (f" (valid keys: {', '.join(sorted(fields))})"
                                                     if not suggestion and fields else "")
        elif err["type"] == "missing":
            message = "required key is missing"
        elif err["type"] in ("literal_error", "enum"):
            message = message.replace("Input should be", "expected")
            opts = re.findall(r"'([^']+)'", err["msg"])
            suggestion = suggest(str(err.get("input")), opts) if opts else None
        elif err["type"] in ("model_type", "model_attributes_type", "dict_type"):  # no Python class names
            message = "expected a table (`[name]`, `[[name]]` or `{ key = value }`)"
        else:
            message = message.replace("Input should be", "expected")
            if err["type"] in ("value_error", "assertion_error"):  # a validator's own words, without pydantic's prefix
                message = re.sub(r"^(Value error|Assertion failed), ", "", message)
        line = locate_line(text, text_base + loc) if text else None
        value = err.get("input") if err["type"] not in ("missing",) and not keys else None
        if err["type"] == "extra_forbidden" or isinstance(value, dict):
            value = None if isinstance(value, dict) else value
        problems.append(Problem(file, format_key(list(prefix) + loc), message, value, suggestion, line))
    return problems


def _fields_at(model: type[BaseModel], loc: Sequence[Any]) -> list[str]:
    """Field names of the (nested) model found by following ``loc``."""
    current: Any = model
    for part in loc:
        if isinstance(part, int):
            continue
        fields = getattr(current, "model_fields", None)
        if not fields or part not in fields:
            return []
        current = _model_in(fields[part].annotation)
    fields = getattr(current, "model_fields", None)
    return list(fields) if fields else []


def _model_in(annotation: Any) -> Any:
    """The first BaseModel class inside an annotation such as ``list[Foo] | None``."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        found = _model_in(arg)
        if found is not None:
            return found
    return None


def validate(model: type[BaseModel], data: Any, file: str, prefix: Sequence[Any] = (),
             text: str | None = None, context: dict | None = None) -> BaseModel:
    """Validate ``data`` against ``model``; raise :class:`ConfigError` with every problem.

    ``context`` reaches the model's validators as ``info.context`` (``fixed_dt``, ``configs_root``).
    """
    try:
        return model.model_validate(data, context=context)
    except ValidationError as exc:
        raise ConfigError(model_problems(exc, model, file, prefix, text, data=data, context=context)) from None


# --------------------------------------------------------------------------- paths
def resolve_inside(root: Path, relative: str, suffix: str = "") -> Path:
    """Resolve ``relative`` under ``root``; refuse absolute paths and anything escaping ``root``."""
    root = Path(root).resolve()
    rel = Path(relative)
    if rel.is_absolute() or relative.startswith(("/", "\\")) or ":" in relative:
        raise ValueError(f"path '{relative}' must be relative to the configs root {root}")
    if suffix and rel.suffix != suffix:
        rel = rel.with_name(rel.name + suffix)
    longest = max((len(os.fsencode(part)) for part in rel.parts), default=0)
    if longest > NAME_MAX or len(os.fsencode(str(root / rel))) > PATH_MAX:  # the OS refuses them (ENAMETOOLONG)
        raise ValueError(f"path '{relative[:40]}...' is too long: a file or folder name may have at most "
                         f"{NAME_MAX} bytes, a whole path {PATH_MAX}")
    candidate = (root / rel).resolve()
    try:
        candidate.relative_to(root)
    except ValueError:
        raise ValueError(f"path '{relative}' escapes the configs root {root}") from None
    return candidate


NAME_MAX, PATH_MAX = 255, 4096  # bytes: Linux's limits, and the usual ones elsewhere
STOCK_CONFIGS = Path(__file__).resolve().parents[1] / "configs"  # the engine's own configs (stock presets, assets)


def resolve_asset(root: Path, relative: str) -> Path:
    """An asset file (height map, texture) named relative to the configs root: the game's own when it has the
    file, else the engine's stock one of the same name (so a stock preset that names a stock asset works in a game
    kept in its own folder, as the presets do); the game's path when neither exists, for the error message.
    Refuses absolute paths and escapes as :func:`resolve_inside` does."""
    path = resolve_inside(root, relative)
    if not path.is_file() and Path(root).resolve() != STOCK_CONFIGS.resolve():
        stock = resolve_inside(STOCK_CONFIGS, relative)
        if stock.is_file():
            return stock
    return path


def as_data(value: Any) -> Any:
    """A value a script passed (tuples, numpy arrays and scalars) as TOML-like data for validation: sequences as
    lists, numpy scalars as Python numbers; strings stay strings (and a vector field refuses them)."""
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return value.tolist()  # numpy arrays and scalars
    if isinstance(value, tuple):
        return [as_data(v) for v in value]
    return value


def deep_merge(base: dict, override: dict) -> dict:
    """``override`` on top of ``base``; nested tables merge, everything else replaces."""
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = value
    return out

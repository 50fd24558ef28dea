"""Load a YAML file into a pydantic model and report EVERY problem with its place in the file.

A person editing a mission file needs to know where each mistake is, all at once, not one per run.
PyYAML's *composed* node tree keeps the start mark (line, column) of every key and value, so we
compose the document, build plain Python data from the nodes ourselves (recording where each key
path lives), validate with pydantic, and map each validation error's ``loc`` back to a mark.

Every message has the form ``file:line:col key.path: message`` (1-based line and column), which
editors and terminals turn into clickable links.
"""
from __future__ import annotations

import difflib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from fsw import safe_yaml
from fsw.safe_yaml import MAX_FILE_BYTES

Loc = tuple[str | int, ...]
ModelT = TypeVar("ModelT", bound=BaseModel)


@dataclass(frozen=True)
class Problem:
    """One problem in a config file: where it is and what is wrong."""

    file: str
    line: int  # 1-based
    col: int  # 1-based
    path: str  # dotted key path, e.g. "flight_software.zones[1].half_angle_deg"
    message: str

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}:{self.col}"
        return f"{where} {self.path}: {self.message}" if self.path else f"{where}: {self.message}"


class ConfigError(Exception):
    """A config file has problems; ``problems`` lists them all, ``str()`` prints one per line."""

    def __init__(self, problems: list[Problem]):
        self.problems = sorted(problems, key=lambda p: (p.file, p.line, p.col, p.path))
        super().__init__("\n".join(str(p) for p in self.problems))


@dataclass
class Marked:
    """Plain data from a YAML document plus the start mark of every key and value."""

    data: Any
    file: str
    value_marks: dict[Loc, tuple[int, int]] = field(default_factory=dict)  # 1-based (line, col)
    key_marks: dict[Loc, tuple[int, int]] = field(default_factory=dict)

    def mark_for(self, loc: Loc, *, prefer_key: bool = False) -> tuple[int, int]:
        """Best (line, col) for ``loc``: the deepest prefix of it that exists in the document."""
        for end in range(len(loc), -1, -1):
            prefix = tuple(loc[:end])
            if prefer_key and end == len(loc) and prefix in self.key_marks:
                return self.key_marks[prefix]
            if prefix in self.value_marks:
                return self.value_marks[prefix]
        return (1, 1)


def format_path(loc: Loc) -> str:
    """("a", 0, "b") -> "a[0].b"."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def _mark(node: yaml.Node) -> tuple[int, int]:
    return (node.start_mark.line + 1, node.start_mark.column + 1)


def _build(node: yaml.Node, loc: Loc, doc: Marked, problems: list[Problem],
           constructor: yaml.constructor.SafeConstructor) -> Any:
    doc.value_marks[loc] = _mark(node)
    if isinstance(node, yaml.MappingNode):
        out: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                problems.append(Problem(doc.file, *_mark(key_node), format_path(loc),
                                        "YAML merge keys (<<) are not supported; write the keys out"))
                continue
            key = constructor.construct_object(key_node, deep=True) if isinstance(key_node, yaml.ScalarNode) else None
            if not isinstance(key, (str, int)) or isinstance(key, bool):
                problems.append(Problem(doc.file, *_mark(key_node), format_path(loc),
                                        "keys must be plain strings"))
                continue
            child = loc + (key,)
            if key in out:
                first = doc.key_marks[child]
                problems.append(Problem(doc.file, *_mark(key_node), format_path(child),
                                        f"duplicate key (first given at line {first[0]}); "
                                        "YAML would silently keep only the last one"))
            doc.key_marks[child] = _mark(key_node)
            out[key] = _build(value_node, child, doc, problems, constructor)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_build(item, loc + (i,), doc, problems, constructor) for i, item in enumerate(node.value)]
    # Scalars: let PyYAML's safe constructor resolve ints, floats, bools, null, timestamps.
    return constructor.construct_object(node, deep=True)


class ConfigFileError(ConfigError):
    """The file itself cannot be read (missing, a directory, a FIFO, unreadable, too large): the
    commands exit 2 for it, as for a rejected mission, rather than 1 (a problem in its content)."""


def read_config_text(path: str | Path) -> str:
    """`fsw.safe_yaml.read_config_text`, its refusal as a ConfigFileError naming the file."""
    try:
        return safe_yaml.read_config_text(path)
    except safe_yaml.UnreadableFile as exc:
        raise ConfigFileError([Problem(str(path), 1, 1, "", str(exc))]) from None


def syntax_problem(name: str, text: str, exc: yaml.MarkedYAMLError) -> Problem:
    """A YAML syntax error as a Problem in plain words, with the fix, at the place to change.

    PyYAML's own words ("expected <block end>, but found '<block mapping start>'") describe its parser
    state, not the file; the common mistakes (a tab, a key indented differently from its neighbours, an
    unclosed bracket or quote) are recognised and explained against the lines above.
    """
    mark = exc.problem_mark or exc.context_mark
    line, col = (mark.line + 1, mark.column + 1) if mark else (1, 1)
    problem = str(exc.problem or "")
    context_at = exc.context_mark
    lines = text.splitlines()
    if "'\\t'" in problem:
        return Problem(name, line, col, "", "a tab character: YAML does not allow tabs here; use spaces for "
                       "indentation (and after ':')")
    if mark is not None and ("mapping values are not allowed" in problem or "expected <block end>" in problem):
        hint = _indentation_hint(lines, mark.line)
        if hint is not None:
            return Problem(name, mark.line + 1, hint[0], "", hint[1])
    if "mapping values are not allowed" in problem:
        return Problem(name, line, col, "", "a second ':' on this line: a value that contains ': ' must be "
                       "quoted, e.g. key: 'a: b'")
    if context_at is not None and "flow sequence" in str(exc.context):
        return Problem(name, line, col, "", f"the '[' opened at line {context_at.line + 1}, column "
                       f"{context_at.column + 1} is not closed: end the list with ']' on its line")
    if context_at is not None and "flow mapping" in str(exc.context):
        return Problem(name, line, col, "", f"the '{{' opened at line {context_at.line + 1}, column "
                       f"{context_at.column + 1} is not closed: end the mapping with '}}' on its line")
    if context_at is not None and "quoted scalar" in str(exc.context):
        return Problem(name, context_at.line + 1, context_at.column + 1, "", "this quote is never closed: add "
                       "the matching quote at the end of the value")
    what = str(exc.context or "").replace("while parsing a ", "").replace("while scanning a ", "")
    where = (f" (in the {what} that starts at line {context_at.line + 1})"
             if context_at is not None and what else "")
    return Problem(name, line, col, "", f"YAML syntax error: {problem}{where}")


def _content_lines(lines: list[str], before: int) -> list[tuple[int, int, str]]:
    """(line index, indent, text) of the lines before ``before`` that hold YAML, nearest first."""
    out = []
    for i in range(min(before, len(lines)) - 1, -1, -1):
        stripped = lines[i].strip()
        if stripped and not stripped.startswith("#"):
            out.append((i, len(lines[i]) - len(lines[i].lstrip(" ")), stripped))
    return out


def _columns(indent: int, text: str) -> list[tuple[int, str]]:
    """The columns a line opens, with how to name them: a key, or a list item and the key inside it."""
    if text.startswith("- ") or text == "-":
        item = text if len(text) <= 24 else text[:21] + "..."
        out = [(indent, f"the list item '{item}'")]
        rest = text[1:].lstrip(" ")
        if rest and ":" in rest and not rest.startswith(("{", "[", "'", '"')):
            out.append((indent + len(text) - len(rest), "'" + rest.split(":", 1)[0].strip() + "'"))
        return out
    return [(indent, "'" + text.split(":", 1)[0].strip() + "'")]


def _spaces(n: int) -> str:
    return f"{n} space" + ("" if n == 1 else "s")


def _indentation_hint(lines: list[str], index: int) -> tuple[int, str] | None:
    """(column, message) when line ``index`` is a key or list item indented unlike the lines above it."""
    if index >= len(lines) or index == 0:
        return None
    raw = lines[index]
    indent = len(raw) - len(raw.lstrip(" "))
    text = raw.strip()
    if not text or (":" not in text and not text.startswith("-")):
        return None
    above = _content_lines(lines, index)
    if not above:
        return None
    me = _columns(indent, text)[0][1]
    prev_i, prev_indent, prev_text = above[0]
    prev_col, prev_label = _columns(prev_indent, prev_text)[-1]
    if indent > prev_col:
        if prev_text.rstrip().endswith(":"):
            return None  # a child of a mapping key: not an indentation problem
        return (indent + 1, f"{me} is indented {_spaces(indent)}, more than {prev_label} on line {prev_i + 1} "
                f"({_spaces(prev_col)}), which already has a value, so YAML reads this line as part of that "
                f"value; indent it {_spaces(prev_col)} to line up with {prev_label}")
    # the columns it could line up with: those opened by the enclosing lines above
    columns: list[tuple[int, str, int]] = []
    lowest = prev_col + 1
    for i, ind, t in above:
        if ind < lowest:
            columns += [(c, label, i + 1) for c, label in _columns(ind, t) if c < lowest]
            lowest = ind
        if ind == 0:
            break
    if any(c == indent for c, _, _ in columns):
        return None
    deeper = sorted((c for c in columns if c[0] > indent), key=lambda c: c[0])[:1]
    shallower = sorted((c for c in columns if c[0] < indent), key=lambda c: -c[0])[:1]
    choices = deeper + shallower
    seen = ", ".join(f"{label} (line {n}) at {_spaces(c)}" for c, label, n in choices)
    fix = " or ".join(f"{_spaces(c)} to line up with {label}" for c, label, _ in choices)
    return (indent + 1, f"{me} is indented {_spaces(indent)}, which lines up with nothing above it ({seen}): "
            f"the keys of one mapping, and the items of one list, must start in the same column; indent it {fix}")


def load_marked(path: str | Path, text: str | None = None) -> Marked:
    """Compose ``path`` (or ``text`` named as ``path``) and return its data with marks.

    Raises ConfigFileError when the file cannot be read (see `read_config_text`), ConfigError for YAML
    syntax errors, duplicate keys, more than one document, a document that is not a mapping, or one
    beyond the size, depth and alias limits.
    """
    name = str(path)
    if text is None:
        text = read_config_text(path)
    elif len(text) > MAX_FILE_BYTES:
        raise ConfigFileError([Problem(name, 1, 1, "", f"larger than {MAX_FILE_BYTES // 2**20} MB, the limit "
                                       "for a config file")])
    try:
        nodes = safe_yaml.compose_all(text)
    except safe_yaml.LimitExceeded as exc:
        raise ConfigError([Problem(name, exc.mark.line + 1, exc.mark.column + 1, "", exc.message)]) from None
    except yaml.MarkedYAMLError as exc:
        raise ConfigError([syntax_problem(name, text, exc)]) from None
    except yaml.YAMLError as exc:
        raise ConfigError([Problem(name, 1, 1, "", f"YAML error: {exc}")]) from None
    if not nodes:
        raise ConfigError([Problem(name, 1, 1, "", "the file is empty; expected a mapping of keys")])
    if len(nodes) > 1:
        raise ConfigError([Problem(name, *_mark(nodes[1]), "",
                                   "more than one YAML document (---); a mission is one document")])
    root = nodes[0]
    if not isinstance(root, yaml.MappingNode):
        raise ConfigError([Problem(name, *_mark(root), "",
                                   f"the top level must be a mapping of keys, got a {root.id}")])
    try:
        safe_yaml.check_expansion(root)  # before building: aliases inside aliases expand geometrically
    except safe_yaml.LimitExceeded as exc:
        raise ConfigError([Problem(name, exc.mark.line + 1, exc.mark.column + 1, "", exc.message)]) from None
    doc = Marked(data=None, file=name)
    problems: list[Problem] = []
    constructor = yaml.SafeLoader("")  # only its construct_object is used
    try:
        doc.data = _build(root, (), doc, problems, constructor)
    except yaml.constructor.ConstructorError as exc:
        mark = exc.problem_mark
        problems.append(Problem(name, mark.line + 1 if mark else 1, mark.column + 1 if mark else 1, "",
                                f"YAML value error: {exc.problem}"))
    if problems:
        raise ConfigError(problems)
    return doc


# ---------------------------------------------------------------------------------------------
# Mapping pydantic errors onto the document
# ---------------------------------------------------------------------------------------------

def _unwrap(annotation: Any) -> list[Any]:
    """The model classes an annotation can hold (through Optional, list, dict, Annotated, Union)."""
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        return _unwrap(typing.get_args(annotation)[0])
    if origin in (typing.Union, types.UnionType):
        return [m for arg in typing.get_args(annotation) for m in _unwrap(arg)]
    if origin in (list, tuple, set, frozenset, dict):
        return [m for arg in typing.get_args(annotation) for m in _unwrap(arg)]
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return []


def _model_at(root: type[BaseModel], loc: Loc) -> type[BaseModel] | None:
    """The model class that validates the mapping found at ``loc`` (skipping union tags)."""
    current: list[type[BaseModel]] = [root]
    for part in loc:
        if isinstance(part, int):
            continue  # list index: same element type
        nxt: list[type[BaseModel]] = []
        for model in current:
            if part in model.model_fields:
                nxt.extend(_unwrap(model.model_fields[part].annotation))
        if nxt:
            current = nxt
            continue
        # a discriminated-union tag (e.g. "cone") names one of the current candidates
        tagged = [m for m in current if _tag_of(m) == part]
        if tagged:
            current = tagged
            continue
        return None
    return current[0] if len(current) == 1 else None


def _tag_of(model: type[BaseModel]) -> str | None:
    for name in ("kind", "type", "shape", "command"):
        info = model.model_fields.get(name)
        if info is not None:
            args = typing.get_args(info.annotation)
            if len(args) == 1 and isinstance(args[0], str):
                return args[0]
    return None


def _data_loc(doc: Marked, loc: Loc) -> Loc:
    """Drop parts of a pydantic loc that are not in the data (union tags, 'function-after[...]')."""
    out: list[str | int] = []
    node: Any = doc.data
    for i, part in enumerate(loc):
        if isinstance(node, dict) and part in node:
            out.append(part)
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
            out.append(part)
            node = node[part]
        elif i == len(loc) - 1 and isinstance(node, dict) and isinstance(part, str) and not _looks_internal(part):
            out.append(part)  # a missing key: keep it in the path, the mark falls back to its parent
        # else: an internal component (union tag, validator name): skip
    return tuple(out)


def _looks_internal(part: str) -> bool:
    return "[" in part or part.startswith("function-")


def _describe_input(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def problems_from_validation(doc: Marked, exc: ValidationError, model: type[BaseModel]) -> list[Problem]:
    """Turn every pydantic error into a Problem with a file position and an actionable message."""
    out: list[Problem] = []
    seen: set[tuple[Loc, str]] = set()
    for err in exc.errors(include_url=False):
        raw_loc: Loc = tuple(err.get("loc", ()))
        loc = _data_loc(doc, raw_loc)
        kind = err.get("type", "")
        msg = str(err.get("msg", "invalid"))
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        if msg.startswith("Assertion failed, "):
            msg = msg[len("Assertion failed, "):]
        if kind == "extra_forbidden":
            parent = _model_at(model, raw_loc[:-1])
            allowed = sorted(parent.model_fields) if parent else []
            key = str(raw_loc[-1])
            msg = f"unknown key '{key}'"
            close = difflib.get_close_matches(key, allowed, n=1)
            if close:
                msg += f" (did you mean '{close[0]}'?)"
            if allowed:
                msg += "; allowed here: " + ", ".join(allowed)
            line, col = doc.mark_for(loc, prefer_key=True)
        elif kind in ("union_tag_invalid", "union_tag_not_found"):
            ctx = err.get("ctx", {})
            tag_key = str(ctx.get("discriminator", "")).strip("'\"")
            allowed = [t.strip(" '\"") for t in str(ctx.get("expected_tags", "")).split(",") if t.strip()]
            if kind == "union_tag_invalid":
                got = str(ctx.get("tag", ""))
                msg = f"unknown {tag_key} '{got}'"
                close = difflib.get_close_matches(got, allowed, n=1)
                if close:
                    msg += f" (did you mean '{close[0]}'?)"
                loc = loc + (tag_key,)
            else:
                msg = f"required key '{tag_key}' is missing"
            msg += "; allowed: " + ", ".join(allowed)
            line, col = doc.mark_for(loc)
        elif kind == "missing":
            parent = tuple(loc[:-1]) if loc and loc[-1] == raw_loc[-1] else loc
            msg = f"required key '{raw_loc[-1]}' is missing"
            line, col = doc.mark_for(parent)
        else:
            if "input" in err and kind not in ("union_tag_invalid",) and not isinstance(err["input"], (dict, list)):
                msg += f" (got {_describe_input(err['input'])})"
            line, col = doc.mark_for(loc)
        dedupe = (loc, msg)
        if dedupe in seen:
            continue
        seen.add(dedupe)
        out.append(Problem(doc.file, line, col, format_path(loc), msg))
    return out


def load_model(path: str | Path, model: type[ModelT], *, text: str | None = None) -> ModelT:
    """Load and validate ``path`` as ``model``; raise ConfigError listing every problem found."""
    doc = load_marked(path, text)
    try:
        return model.model_validate(doc.data)
    except ValidationError as exc:
        raise ConfigError(problems_from_validation(doc, exc, model)) from None

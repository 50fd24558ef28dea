"""Reading a YAML config file so that no file can hang or exhaust the reader.

Shared by the flight software (``python -m fsw`` reads its own configuration file with it) and by
`hil_sim.mission.loader`, the one mission reader (``config validate``, ``sil run``, ``keepout fsw MISSION``,
campaigns), which adds the positions of every key.
A file is refused when it is not a regular file (a FIFO would block the open forever), when it is larger
than MAX_FILE_BYTES or has more than MAX_LINES lines (both before parsing), holds more than
MAX_COMPOSED_NODES values, is nested deeper than MAX_DEPTH or uses more than MAX_ALIASES aliases (these three
counted while composing, so the refusal comes as soon as a limit is passed), or expands (aliases repeating
aliases, a "billion laughs") to more than MAX_NODES values.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

import yaml

MAX_FILE_BYTES = 1024 * 1024  # a mission is a few kB; anything this big is a mistake or an attack
MAX_ALIASES = 100  # YAML aliases (*name) allowed in one file: a mission needs none
MAX_DEPTH = 32  # nesting of mappings and lists: a mission nests 6 deep
MAX_NODES = 200_000  # values after alias expansion: stops a "billion laughs" before it costs memory
# Checked before parsing and while composing, so a file is refused as soon as it goes over, whatever its
# shape: PyYAML composes ~25 k values a second, so a 4 MB flat list of 2 M values took 88 s and 1.5 GB
# before the expansion check refused it. The largest shipped config has 410 values and 120 lines.
MAX_LINES = 50_000
MAX_COMPOSED_NODES = 20_000  # values as written (each alias counts once here; expansion: MAX_NODES)


class UnreadableFile(Exception):
    """The file cannot be read as a config file; the message says why in one line (no file name)."""


def read_config_text(path: str | Path) -> str:
    """The text of a config file, refusing anything that could hang or exhaust memory.

    The file is opened non-blocking (opening a FIFO for reading would otherwise wait for a writer
    forever) and checked with fstat on the open descriptor (no race between a check and the open):
    only a regular file of at most MAX_FILE_BYTES is read.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise UnreadableFile("file not found") from None
    except IsADirectoryError:
        raise UnreadableFile("is a directory; give a YAML file") from None
    except PermissionError:
        raise UnreadableFile("permission denied: the file cannot be read (check its permissions)") from None
    except OSError as exc:
        raise UnreadableFile(f"cannot open: {exc.strerror or exc}") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise UnreadableFile("is a directory; give a YAML file")
        if not stat.S_ISREG(info.st_mode):
            raise UnreadableFile("is not a regular file (a FIFO, socket or device); give a YAML file")
        if info.st_size > MAX_FILE_BYTES:
            raise UnreadableFile(f"is {info.st_size / 2**20:.1f} MB; a config file may be at most "
                                 f"{MAX_FILE_BYTES // 2**20} MB")
        os.set_blocking(fd, True)
        with os.fdopen(fd, "rb", closefd=True) as handle:
            fd = -1
            raw = handle.read(MAX_FILE_BYTES + 1)  # the file may have grown since fstat
    except OSError as exc:
        raise UnreadableFile(f"cannot read: {exc.strerror or exc}") from None
    finally:
        if fd >= 0:
            os.close(fd)
    if len(raw) > MAX_FILE_BYTES:
        raise UnreadableFile(f"is larger than {MAX_FILE_BYTES // 2**20} MB, the limit for a config file")
    lines = raw.count(b"\n")
    if lines > MAX_LINES:
        raise UnreadableFile(f"has {lines} lines; a config file may have at most {MAX_LINES} (a mission has ~150)")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UnreadableFile(f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None


class LimitExceeded(yaml.YAMLError):
    """A document beyond the depth, alias or expansion limits; ``mark`` is where (PyYAML Mark)."""

    def __init__(self, message: str, mark: Any):
        super().__init__(message)
        self.message, self.mark = message, mark


class BoundedLoader(yaml.SafeLoader):
    """PyYAML's safe loader with the nesting depth and the number of aliases bounded while composing
    (its composer recurses once per level: 100 k levels would end in a RecursionError)."""

    def __init__(self, stream: str):
        super().__init__(stream)
        self._depth = 0
        self._aliases = 0
        self._nodes = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        self._nodes += 1
        if self._nodes > MAX_COMPOSED_NODES:
            raise LimitExceeded(f"more than {MAX_COMPOSED_NODES} values (keys, items and scalars); a mission "
                                f"has a few hundred", self.peek_event().start_mark)
        if self.check_event(yaml.AliasEvent):
            self._aliases += 1
            if self._aliases > MAX_ALIASES:
                raise LimitExceeded(f"more than {MAX_ALIASES} YAML aliases (*name); write the values out",
                                    self.peek_event().start_mark)
            return super().compose_node(parent, index)
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise LimitExceeded(f"nested more than {MAX_DEPTH} levels deep; a mission nests about 6",
                                    self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


def compose_all(text: str) -> list[yaml.Node]:
    """The documents of ``text`` as node graphs, within the depth and alias limits."""
    loader = BoundedLoader(text)
    try:
        nodes = []
        while loader.check_node():
            nodes.append(loader.get_node())
        return nodes
    finally:
        loader.dispose()


def check_expansion(node: yaml.Node) -> None:
    """Refuse a node graph that expands (aliases counted every time they are used) beyond MAX_NODES."""
    sizes: dict[int, int] = {}

    def size(n: yaml.Node) -> int:
        if id(n) not in sizes:
            sizes[id(n)] = 1  # a cycle (a recursive alias) counts once, then the total overflows anyway
            children = ([c for pair in n.value for c in pair] if isinstance(n, yaml.MappingNode) else
                        list(n.value) if isinstance(n, yaml.SequenceNode) else [])
            sizes[id(n)] = 1 + sum(size(c) for c in children)
        return sizes[id(n)]

    if size(node) > MAX_NODES:
        raise LimitExceeded(f"the document expands to more than {MAX_NODES} values (YAML aliases repeating "
                            "aliases?); write the values out", node.start_mark)


def load_config_file(path: str | Path) -> Any:
    """The data of a one-document YAML config file, within every limit; raises UnreadableFile or a
    yaml.YAMLError (LimitExceeded included)."""
    nodes = compose_all(read_config_text(path))
    if not nodes:
        return None
    if len(nodes) > 1:
        raise LimitExceeded("more than one YAML document (---); a config file is one document", nodes[1].start_mark)
    check_expansion(nodes[0])
    return yaml.SafeLoader("").construct_document(nodes[0])

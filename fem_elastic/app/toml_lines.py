"""Where each key of a TOML text is written: a small scanner of (valid) TOML text.

:class:`KeyLines` gives the 1-based line of every table header, key and array
element, by the same paths :class:`fem_elastic.app.schema_types.Invalid` uses,
so that :mod:`fem_elastic.app.scene` can say where a scene file is wrong.
"""

from __future__ import annotations

import bisect
import re

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]  # the same API on Python 3.10

__all__ = ["KeyLines"]


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


class KeyLines:
    """Line of every table header, key and array element of a TOML text.

    ``lines[path]`` with ``path`` a tuple of keys and array indices, as in
    :class:`fem_elastic.app.scene_schema.Invalid`. Only run on text that tomllib
    has parsed, so the scanner can trust the syntax.
    """

    def __init__(self, text: str):
        self.text = text
        self.n = len(text)
        self.i = 0
        self.newlines = [m.start() for m in re.finditer("\n", text)]
        self.lines: dict[tuple, int] = {}
        self.tables: dict[tuple, int] = {}  # array-of-tables path -> index of its last element
        try:
            self._document()
        except (IndexError, ValueError):  # pragma: no cover - keep what was found
            pass

    def line(self, pos: int) -> int:
        return bisect.bisect_left(self.newlines, pos) + 1

    def _record(self, path: tuple, pos: int) -> None:
        self.lines.setdefault(path, self.line(pos))

    def _skip(self, newlines: bool) -> None:
        t = self.text
        while self.i < self.n:
            c = t[self.i]
            if c in " \t\r" or (newlines and c == "\n"):
                self.i += 1
            elif c == "#":
                end = t.find("\n", self.i)
                self.i = self.n if end < 0 else end
            else:
                break

    def _string(self) -> str:
        t, i = self.text, self.i
        for quote in ('"""', "'''"):
            if t.startswith(quote, i):
                end = t.find(quote, i + 3)
                while quote == '"""' and end > 0 and _escaped(t, end):
                    end = t.find(quote, end + 1)
                end += 3
                while end < self.n and t[end] == quote[0]:  # up to two quotes end the content
                    end += 1
                self.i = end
                return t[i + 3:end - 3]
        q = t[i]
        j = i + 1
        while t[j] != q or (q == '"' and _escaped(t, j)):
            j += 1
        self.i = j + 1
        raw = t[i + 1:j]
        if q == '"':
            try:
                raw = tomllib.loads(f"k = {t[i:j + 1]}")["k"]
            except tomllib.TOMLDecodeError:  # pragma: no cover
                pass
        return raw

    def _key(self) -> tuple:
        parts = []
        while True:
            self._skip(False)
            c = self.text[self.i]
            if c in "\"'":
                parts.append(self._string())
            else:
                m = _BARE_KEY.match(self.text, self.i)
                assert m is not None  # a TOML key that is not quoted is a bare key (was m.group() on None)
                parts.append(m.group())
                self.i = m.end()
            self._skip(False)
            if self.i < self.n and self.text[self.i] == ".":
                self.i += 1
                continue
            return tuple(parts)

    def _resolve(self, keys: tuple) -> tuple:
        path: tuple = ()
        for k in keys:
            path += (k,)
            if path in self.tables:
                path += (self.tables[path],)
        return path

    def _document(self) -> None:
        t = self.text
        current: tuple = ()
        while True:
            self._skip(True)
            if self.i >= self.n:
                return
            start = self.i
            if t.startswith("[[", self.i):
                self.i += 2
                keys = self._key()
                self.i += 2  # "]]"
                parent = self._resolve(keys[:-1])
                path = parent + (keys[-1],)
                index = self.tables.get(path, -1) + 1
                self.tables[path] = index
                current = path + (index,)
                self._record(path, start)
                self._record(current, start)
            elif t[self.i] == "[":
                self.i += 1
                keys = self._key()
                self.i += 1  # "]"
                current = self._resolve(keys)
                for k in range(1, len(current) + 1):
                    self._record(current[:k], start)
            else:
                self._pair(current)

    def _pair(self, table: tuple) -> None:
        start = self.i
        keys = self._key()
        self._skip(False)
        self.i += 1  # "="
        for k in range(1, len(keys) + 1):
            self._record(table + keys[:k], start)
        self._value(table + keys)

    def _value(self, path: tuple) -> None:
        self._skip(False)
        t = self.text
        c = t[self.i]
        if c in "\"'":
            self._string()
        elif c == "[":
            self.i += 1
            index = 0
            while True:
                self._skip(True)
                if t[self.i] == "]":
                    self.i += 1
                    return
                self._record(path + (index,), self.i)
                self._value(path + (index,))
                self._skip(True)
                if t[self.i] == ",":
                    self.i += 1
                    index += 1
        elif c == "{":
            self.i += 1
            while True:
                self._skip(False)
                if t[self.i] == "}":
                    self.i += 1
                    return
                self._pair(path)
                self._skip(False)
                if t[self.i] == ",":
                    self.i += 1
        else:  # number, boolean, date: up to the next delimiter
            while self.i < self.n and t[self.i] not in ",]}\n#":
                self.i += 1


def _escaped(text: str, pos: int) -> bool:
    """Whether the character at ``pos`` is escaped by an odd number of backslashes."""
    n = 0
    while pos - 1 - n >= 0 and text[pos - 1 - n] == "\\":
        n += 1
    return n % 2 == 1

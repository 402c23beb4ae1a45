"""Versioned file formats: what the toolkit writes carries the version of its layout, and each
kind of file has one reader that upgrades older layouts to today's, one step per version.

A writer stamps its data (`Format.stamp`); a reader passes what it loaded through `Format.read`,
which applies `upgrades[v]` for every version v from the data's own (0 where it names none: the
files written before versions were kept) up to `Format.version`. Every "written before X existed"
rule of a format lives in its upgrade functions, next to the format, not in the code that uses
the data. A file from a newer toolkit than this one is refused in one line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from rasterize.errors import InputError

VERSION_KEY = "format_version"


@dataclass(frozen=True)
class Format:
    """One kind of file. `upgrades[v]` turns a version-v mapping into a version-(v + 1) one (it
    returns a new dict; the caller's is left alone), so `version == len(upgrades)`."""

    name: str                                       # what the file is, for messages
    upgrades: tuple[Callable[[dict], dict], ...]    # upgrades[v]: version v -> v + 1

    @property
    def version(self) -> int:
        return len(self.upgrades)

    def stamp(self, data: dict) -> dict:
        """`data` with today's version, for writing."""
        return {**data, VERSION_KEY: self.version}

    def read(self, data: dict, where: object = None) -> dict:
        """`data` (as loaded, of any version up to today's) in today's layout, stamped with
        today's version. `where` names the file in the message for a version this toolkit does
        not know."""
        found = data.get(VERSION_KEY, 0)
        if isinstance(found, bool) or not isinstance(found, int) or found < 0:
            raise InputError(f"{where or 'the ' + self.name} has {VERSION_KEY}={found!r}, not a "
                             f"version of a {self.name}; write it again with this toolkit")
        if found > self.version:
            raise InputError(f"{where or 'the ' + self.name} is a {self.name} of version {found}, "
                             f"newer than this toolkit reads ({self.version}); install the toolkit "
                             "version that wrote it, or pass a file this one wrote")
        out = dict(data)
        for upgrade in self.upgrades[found:]:
            out = upgrade(out)
        out[VERSION_KEY] = self.version
        return out

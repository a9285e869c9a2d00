"""Near duplicates during a run: the accepted shapes' descriptors, shared with the workers.

The parent, the catalogue's only writer, decides; the workers read what it published
(:class:`AcceptedDescriptors`) only to stop early at the near-duplicate check.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from surfgen.filters.descriptor import (
    DescriptorSet,
    descriptor_from_text,
)

log = logging.getLogger(__name__)

ACCEPTED_FILE = "accepted-descriptors.tsv"  # in the staging folder: see AcceptedDescriptors


def near_duplicate(row: dict[str, Any], known: DescriptorSet, threshold: float) -> str | None:
    """The key of the accepted shape nearest to ``row``'s if it is within ``threshold``."""
    return known.within(descriptor_from_text(row["descriptor"]), threshold)[0]


class AcceptedDescriptors:
    """A worker's view of the accepted shapes' descriptors: the parent appends each one's
    key and descriptor text to a file in the run's staging folder (:func:`publish`), as it
    commits them; :meth:`near` reads what was added since it last looked and says whether a
    descriptor is within ``threshold`` of one of them, so the worker can stop at the
    near-duplicate check.

    Every shape it holds is in the parent's :class:`DescriptorSet` too, with the descriptor
    stored with the row, so the parent, which checks against all of them, reaches the same
    verdict: the worker only saves the later checks' time. (A file, not the catalogue: SQLite
    connections do not survive the fork that starts the workers.)"""

    def __init__(self, path: Path, threshold: float) -> None:
        self.path, self.threshold = Path(path), float(threshold)
        self._known = DescriptorSet()
        self._offset = 0

    def __getstate__(self) -> dict[str, Any]:
        return {"path": self.path, "threshold": self.threshold}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["path"], state["threshold"])

    def near(self, values: np.ndarray) -> bool:
        try:
            self._refresh()
        except OSError as exc:  # no file yet, or gone: the parent decides alone
            log.debug("accepted descriptors not read (%s)", exc)
        return self._known.within(values, self.threshold)[0] is not None

    def _refresh(self) -> None:
        with open(self.path, "rb") as f:
            f.seek(self._offset)
            data = f.read()
        end = data.rfind(b"\n") + 1  # whole lines only: the parent may be writing the next
        for line in data[:end].decode("utf-8", errors="replace").splitlines():
            key, _, text = line.partition("\t")
            values = descriptor_from_text(text)
            if values is not None:
                self._known.add(key, values)
        self._offset += end


def publish(path: Path, rows: list[tuple[str, str]]) -> None:
    """Append accepted shapes' ``(key, descriptor text)`` for :class:`AcceptedDescriptors`.

    Only an optimisation: if it cannot be written (a full disk), the workers know less and
    the parent, which decides, goes on; a failed append leaves at most a partial last line,
    which the readers skip until a newline ends it."""
    try:
        with open(path, "a", encoding="utf-8") as f:
            f.write("".join(f"{key}\t{text}\n" for key, text in rows))
    except OSError as exc:
        log.debug("accepted descriptors not published (%s)", exc)

"""Which number of an answer is the model's P(yes): an answer field, keyed where it is a table.

    contact_probability["target:zone"]   P(target touches zone) (asks the contact query for the pair)
    object_fall_probability["target"]    P(target falls)
    any_fall_probability                 P(anything falls)
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from ...engine import ConfigError
from ...engine.errors import shown
from ...engine.query import QUERIES
from ...engine.query.contact import parse_pair

_FORM = re.compile(r"""^\s*(?P<field>[A-Za-z_][A-Za-z0-9_]*)\s*(?:\[\s*(?P<q>["']?)(?P<key>.+?)(?P=q)\s*\])?\s*$""")


@dataclass(frozen=True)
class Readout:
    """``field`` of the answer (keyed by ``key`` where the field is a table), read from ``query``;
    ``contact``: the pair the contact query must be asked for."""

    field: str
    key: str | None
    query: str
    contact: tuple[tuple[str, str], ...] = ()

    def __str__(self) -> str:
        return self.field if self.key is None else f'{self.field}["{self.key}"]'

    def value(self, prediction) -> float:
        """The readout of ``prediction``, a probability; ConfigError("readout") where the answer has none."""
        value = getattr(prediction, self.field)
        if isinstance(value, dict):
            if self.key is None:
                raise ConfigError("readout", f"{self.field} is a table in {prediction.scene}'s answer: name an entry, "
                                             f"e.g. {self.field}[\"{next(iter(value), 'NAME')}\"]")
            if self.key not in value:
                raise ConfigError("readout", f"{prediction.scene}'s answer has no {self} (its {self.field} has "
                                             f"{', '.join(map(repr, value)) or 'no entries'})")
            value = value[self.key]
        elif self.key is not None and value is not None:
            raise ConfigError("readout", f"{self.field} is one number, not a table: write it without [{self.key!r}]")
        if value is None:
            raise ConfigError("readout", f"{prediction.scene}'s answer has no {self.field} "
                                         f"(all of its samples failed: {prediction.failure_reasons[:1]})")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 1 or math.isnan(value):
            raise ConfigError("readout", f"{self} must be a probability, got {shown(value)}")
        return float(value)


def parse_readout(text: str) -> Readout:
    """``field`` or ``field["key"]`` of a probability field of a registered query."""
    found = _FORM.match(text or "")
    if found is None:
        raise ConfigError("readout", f'write FIELD or FIELD["KEY"] (e.g. contact_probability["target:zone"]), '
                                     f"got {shown(text)}")
    field, key = found["field"], found["key"]
    owner = next((name for name, q in QUERIES.items() if field in q.fields), None)
    if owner is None or not (field.endswith("probability") or field == "fall_fraction"):
        usable = sorted(f for q in QUERIES.values() for f in q.fields if f.endswith("probability") or f == "fall_fraction")
        raise ConfigError("readout", f"{field!r} is not a probability an answer gives; one of {', '.join(usable)}")
    if owner == "contact":
        if key is None:
            raise ConfigError("readout", f'{field} needs its pair: {field}["A:B"]')
        a, b = parse_pair(key, "readout")
        return Readout(field, f"{a}:{b}", owner, ((a, b),))
    return Readout(field, key, owner)

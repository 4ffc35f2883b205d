"""The allowed values of a config field, declared once, in the field's own type.

A field of a typed section (``repro/config/schema.py``, a learner's ``section``, an objective's ``params``) declares
what it admits on its own line, in its annotation (PEP 593's ``Annotated``, as pydantic's ``Field`` and
annotated-types' ``Ge`` are written), as CORL's ``TrainConfig`` gives a field its type, default and comment::

    discount: Annotated[float, Bound(ge=0.0, le=1.0)]  # the critic's discount (the YAML gives the value)
    momentum: Annotated[float, Bound(ge=0.0, lt=1.0)] = 0.0  # with a default (an objective's parameter)
    experiment: Annotated[str, A_NAME]  # a run directory component

The annotation's type is what OmegaConf and every reader see (``typing.get_type_hints`` leaves the metadata out);
:func:`repro.config.compose.validate` reads every declared check of a run's fields (:func:`declared`) in one loop,
before anything is built or written; a refusal is one line naming the key, the allowed values and the value given.
Data only: no ``repro`` import, so a plugin's registration module may use it (``repro.config.plugins`` re-exports it).
"""

from __future__ import annotations

import dataclasses
import math
import re
import typing
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Union


def _number(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


@dataclass(frozen=True)
class Bound:
    """The allowed values of a numeric field: ``ge`` / ``gt`` (a lower limit, inclusive / exclusive), ``le`` / ``lt``
    (an upper one), ``finite`` (no infinity), ``even``. NaN is in no bound; a null value is not checked. ``each``:
    the field is a mapping (``agent.objectives``) and every value of it is bounded. ``what``: a noun phrase that
    names what the value is (the refusal then says ``<key> is <what>: <the allowed values>``); ``note``: a clause
    added after the allowed values (``0 disables it``)."""

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    finite: bool = False
    even: bool = False
    each: bool = False
    what: str | None = None
    note: str | None = None

    def __post_init__(self) -> None:
        """ValueError (one line) for a bound that cannot be read: two limits on one side, a limit that is not a
        number, none at all, or a lower limit above the upper one."""
        limits = {"ge": self.ge, "gt": self.gt, "le": self.le, "lt": self.lt}
        for name, limit in limits.items():
            if limit is not None and (not _number(limit) or math.isnan(limit)):
                raise ValueError(f"Bound: {name} must be a number (got {limit!r}).")
        if self.ge is not None and self.gt is not None or self.le is not None and self.lt is not None:
            raise ValueError("Bound: give one lower limit (ge or gt) and one upper limit (le or lt) at most.")
        if self.low is None and self.high is None and not self.finite and not self.even:
            raise ValueError("Bound: give a limit (ge, gt, le or lt), finite or even.")
        if self.low is not None and self.high is not None and self.low > self.high:
            raise ValueError(f"Bound: the lower limit {self.low} is above the upper limit {self.high}.")

    @property
    def low(self) -> float | None:
        return self.ge if self.ge is not None else self.gt

    @property
    def high(self) -> float | None:
        return self.le if self.le is not None else self.lt

    def text(self) -> str:
        """The limits in words: ``> 0.0``, ``>= 1``, ``in (0.0, 1.0)``, ``in [0.0, 1.0)``, ``<= 1.0`` (empty when
        the bound has none)."""
        low, high = self.low, self.high
        if low is not None and high is not None:
            return f"in {'[' if self.ge is not None else '('}{low}, {high}{']' if self.le is not None else ')'}"
        if low is not None:
            return f"{'>=' if self.ge is not None else '>'} {low}"
        if high is not None:
            return f"{'<=' if self.le is not None else '<'} {high}"
        return ""

    def _within_limits(self, value: float) -> bool:
        return not (value != value or self.ge is not None and value < self.ge or self.gt is not None
                    and value <= self.gt or self.le is not None and value > self.le or self.lt is not None
                    and value >= self.lt)

    def admits(self, value: float) -> bool:
        """Whether the number ``value`` is allowed (NaN never is)."""
        if not self._within_limits(value) or self.finite and math.isinf(value):
            return False
        return not self.even or (not math.isinf(value) and value % 2 == 0)

    def refusal(self, key: str, value: Any) -> str | None:
        """The one line refusing ``value`` at ``key`` (each of its entries for an ``each`` bound), None when it is
        allowed or null."""
        if self.each:
            if not isinstance(value, Mapping):
                return None  # the type check names a mapping field given a value
            return next((line for name, entry in value.items()
                         if (line := self._refusal(f"{key}.{name}", entry)) is not None), None)
        return self._refusal(key, value)

    def _refusal(self, key: str, value: Any) -> str | None:
        if value is None:
            return None
        number = _number(value)
        if number and self.admits(value):
            return None
        noun = "an even number" if self.even else "a finite number" if self.finite else "a number"
        if self.what is None and number and not self.even:
            # what is wrong: the limits, or (within them) the infinity
            noun = "a finite number" if self._within_limits(value) else ""
        words = " ".join(w for w in (noun, self.text()) if w)
        if self.note:
            words += f", {self.note}"
        head = f"{key} is {self.what}:" if self.what is not None else f"{key} must be"
        return f"{head} {words} (got {value if number else repr(value)})."


@dataclass(frozen=True)
class Text:
    """The allowed values of a string field: those where the regular expression ``pattern`` is found
    (``re.search``); ``says``: the line refusing another, with ``{key}`` and ``{value}`` filled in."""

    pattern: str
    says: str

    def __post_init__(self) -> None:
        re.compile(self.pattern)  # re.error for a pattern that is not one

    def refusal(self, key: str, value: Any) -> str | None:
        """The one line refusing ``value`` at ``key``, None when it is allowed or null."""
        if value is None or re.search(self.pattern, str(value)):
            return None
        return self.says.format(key=key, value=value)


Check = Union[Bound, Text]

NAME_PATTERN = r"^[A-Za-z0-9_.\-]+$"
# A name that becomes a run directory component (experiment, variant, task and agent names, a dataset kind).
A_NAME = Text(NAME_PATTERN, "{key}='{value}' may only contain letters, digits, '_', '.' and '-'.")


def check_in(annotation: Any) -> Check | None:
    """The check an annotation declares (``Annotated[int, Bound(ge=1)]``, also inside ``Optional[...]``), None when
    it declares none."""
    if typing.get_origin(annotation) is Annotated:
        return next((m for m in annotation.__metadata__ if isinstance(m, (Bound, Text))), None)
    if typing.get_origin(annotation) is Union:
        return next((c for c in map(check_in, typing.get_args(annotation)) if c is not None), None)
    return None


def declared(section: type, prefix: str = "") -> Iterator[tuple[str, Any, Check | None]]:
    """``(dotted key, type, check)`` for every field of the dataclass ``section`` and of its sub-sections, in
    declaration order (the type without its metadata, as OmegaConf reads it); a sub-section is given as itself (its
    dataclass type, no check) before its fields."""
    hints = typing.get_type_hints(section)
    annotated = typing.get_type_hints(section, include_extras=True)
    for field in dataclasses.fields(section):
        kind = hints[field.name]
        yield prefix + field.name, kind, check_in(annotated[field.name])
        if isinstance(kind, type) and dataclasses.is_dataclass(kind):
            yield from declared(kind, f"{prefix}{field.name}.")


def is_mapping(kind: Any) -> bool:
    """Whether a field of type ``kind`` is a mapping (``dict[str, float]``)."""
    return typing.get_origin(kind) in (dict, Mapping)


def numeric(kind: Any) -> bool:
    """Whether a field of type ``kind`` holds numbers (``int``, ``float``, either Optional, or a mapping to them)."""
    if is_mapping(kind):
        return len(typing.get_args(kind)) == 2 and numeric(typing.get_args(kind)[1])
    plain = [a for a in typing.get_args(kind) if a is not type(None)]
    if typing.get_origin(kind) is Union and len(plain) == 1:
        return numeric(plain[0])
    return kind in (int, float)


def check_declarations(section: type) -> str | None:
    """Why the checks ``section`` declares cannot be used (one line), None when they can: a Bound on a field that
    holds no numbers (or an ``each`` Bound on one that is not a mapping), a Text on a field that holds no strings."""
    for key, kind, check in declared(section):
        if check is None:
            continue
        if isinstance(check, Bound) and (not numeric(kind) or check.each != is_mapping(kind)):
            return (f"field '{key}' has a bound but is {getattr(kind, '__name__', kind)}, not "
                    f"{'a mapping to numbers' if check.each else 'a number'}.")
        if isinstance(check, Text) and kind not in (str, Union[str, None]):
            return f"field '{key}' has a text check but is {getattr(kind, '__name__', kind)}, not a string."
    return None

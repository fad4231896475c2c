"""One exception type for every problem a user can fix: it names the file, the problem and the remedy."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


class PhysposeError(Exception):
    """A user-facing error: the CLI prints it without a traceback and exits non-zero.

    The message reads "<where>: <problem>. <remedy>" so a person knows which file (and frame)
    is wrong and what to do about it.
    """

    def __init__(self, problem: str, *, path: str | Path | None = None, frame: int | None = None,
                 remedy: str | None = None):
        self.problem = problem
        self.path = None if path is None else str(path)
        self.frame = frame
        self.remedy = remedy
        where = []
        if self.path is not None:
            where.append(self.path)
        if frame is not None:
            where.append(f"frame {frame}")
        text = (", ".join(where) + ": " if where else "") + problem.rstrip(".") + "."
        if remedy:
            text += " " + remedy.rstrip(".") + "."
        super().__init__(text)


def expect_type(value: object, kind: type | tuple[type, ...], what: str, remedy: str) -> None:
    """PhysposeError unless `value` is a `kind`: at a stage's entry, so that a preset's name
    given where its config belongs, or arguments in the wrong order, fail at once with the
    remedy instead of an AttributeError deep inside (possibly after a long stage)."""
    if not isinstance(value, kind):
        names = " or ".join(k.__name__ for k in (kind if isinstance(kind, tuple) else (kind,)))
        shown = repr(value) if len(repr(value)) <= 40 else repr(value)[:37] + "..."
        raise PhysposeError(f"{what} must be {names}, not {type(value).__name__} {shown}",
                            remedy=remedy)


def check_field(config: object, name: str, ok: bool, rule: str,
                remedy: str | None = None) -> None:
    """PhysposeError naming a config dataclass's field and the rule it breaks unless `ok`;
    the remedy defaults to the field's default value."""
    if not ok:
        value = getattr(config, name)
        default = type(config).__dataclass_fields__[name].default
        raise PhysposeError(f"{type(config).__name__}.{name}={value!r} must be {rule}",
                            remedy=remedy or f"use e.g. {name}={default!r} (the default)")


@contextmanager
def about(path: str | Path, remedy: str | None = None, *,
          instead_of: str | Path | None = None) -> Iterator[None]:
    """A PhysposeError raised inside that names no file, or names ``instead_of``, is about
    ``path`` (a check deep in a stage knows the data, not the file the user gave);
    ``remedy`` where it gave none."""
    try:
        yield
    except PhysposeError as exc:
        if exc.path is not None and (instead_of is None or exc.path != str(instead_of)):
            raise
        raise PhysposeError(exc.problem, path=path, frame=exc.frame,
                            remedy=exc.remedy or remedy) from None

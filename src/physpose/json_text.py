"""JSON text every reader accepts: non-finite numbers as null (JSON has no NaN or Infinity;
Python writes them as bare tokens that browsers and most parsers refuse), NumPy values as
plain lists and numbers."""

from __future__ import annotations

import json
import math
from pathlib import Path

from physpose.errors import PhysposeError


def strict_json(doc, **dumps_options) -> str:
    """``json.dumps`` of doc with every NaN and infinity replaced by null."""
    return json.dumps(_finite(doc), allow_nan=False, **dumps_options)


def _finite(value):
    if hasattr(value, "tolist"):  # NumPy arrays and scalars
        value = value.tolist()
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def read_json_file(path: str | Path, remedy: str):
    """The JSON document in a file, or a PhysposeError naming the file (and the line of a
    syntax error) with `remedy`: unreadable, not UTF-8, not JSON, nested too deep."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except OSError as exc:
        raise PhysposeError(f"cannot read file ({exc})", path=path, remedy=remedy) from None
    except json.JSONDecodeError as exc:
        raise PhysposeError(f"line {exc.lineno}: not valid JSON ({exc.msg})", path=path,
                            remedy=remedy) from None
    except (UnicodeDecodeError, RecursionError) as exc:
        raise PhysposeError(f"not a UTF-8 JSON file ({exc})", path=path,
                            remedy=remedy) from None

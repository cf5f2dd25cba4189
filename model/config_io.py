"""JSON round trip of frozen config dataclasses (nested dataclasses, tuples), atomic writes."""

import dataclasses
import json
import os
import tempfile
import typing
from typing import Any


def to_dict(config: Any) -> dict:
  """A JSON-ready dict of a (nested) config dataclass."""
  return dataclasses.asdict(config)


def from_dict(cls: type, data: dict, where: str = 'config') -> Any:
  """Rebuilds ``cls`` from ``to_dict`` output.

  Args:
    cls: the dataclass type.
    data: a dict as written by ``to_dict`` (lists become tuples).
    where: name used in error messages.

  Returns:
    An instance of ``cls``; missing fields take their defaults. A class with
    a ``from_dict(data)`` classmethod of its own is built by it.

  Raises:
    ValueError: on unknown fields or a non-dict.
  """
  if not isinstance(data, dict):
    raise ValueError(f'{where} must be a JSON object, got {type(data).__name__}.')
  own = getattr(cls, 'from_dict', None)
  if own is not None:  # a config that reads its own (e.g. older) forms
    return own(data)
  hints = typing.get_type_hints(cls)
  names = {f.name for f in dataclasses.fields(cls)}
  unknown = sorted(set(data) - names)
  if unknown:
    raise ValueError(f'{where} has unknown fields {unknown} for {cls.__name__}.')
  kwargs = {}
  for name, value in data.items():
    hint = hints[name]
    if dataclasses.is_dataclass(hint):
      value = from_dict(hint, value, f'{where}.{name}')
    elif typing.get_origin(hint) is tuple and isinstance(value, list):
      value = tuple(tuple(v) if isinstance(v, list) else v for v in value)
    kwargs[name] = value
  return cls(**kwargs)


def write_json(path: str, data: Any) -> None:
  """Writes JSON atomically (temp file in the same folder, then ``os.replace``)."""
  folder = os.path.dirname(os.path.abspath(path))
  os.makedirs(folder, exist_ok=True)
  fd, tmp = tempfile.mkstemp(dir=folder, suffix='.tmp')
  try:
    with os.fdopen(fd, 'w') as f:
      json.dump(data, f, indent=2, sort_keys=True)
      f.write('\n')
    umask = os.umask(0)  # mkstemp's 0600 -> the user's usual mode
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, path)
  except BaseException:
    os.unlink(tmp)
    raise


def read_json(path: str) -> Any:
  """Reads a JSON file, naming the file in the error if it is not valid JSON."""
  with open(path) as f:
    try:
      return json.load(f)
    except json.JSONDecodeError as e:
      raise ValueError(f'{path} is not valid JSON: {e}') from e

"""The recordings of one estimate, each with its own set-up.

A fabric measured by a protocol is seen in recordings that differ in more than
the fan: the 1 m sheet and a small swatch, each filmed by its own camera, each
fan read by an anemometer or not. A joint estimate shares bending and area
weight across them; everything else is the recording's own (``Take``). Short
lists come as flags (``--recording=a,b --cloth_sizes=1,0.25``); longer ones
as a protocol file (JSON or YAML)::

  {"recordings": [
    {"recording": "sheet/depth", "camera_json": "sheet/camera.json",
     "wind_speed": 2.1, "wind_speed_sd": 0.05},
    {"recording": "swatch/depth", "camera_json": "swatch/camera.json",
     "cloth_size": 0.25, "world_up": "z"}
  ],
   "fabric": {"area_weight": 0.212, "area_weight_sd": 0.003,
              "bending_length": 0.021, "bending_length_sd": 0.001}}

A sheet filmed twice at one fan setting, once with a known mass taped along
its free hem, shares that setting's one wind (``"fan"``: a label; the hem's
``"hem_mass"`` in kg): the hem then weighs the cloth against a known mass
rather than through the simulator's drag law (docs/studies/protocol.md)::

  {"recordings": [
    {"recording": "plain/depth", "camera_json": "cam.json", "fan": "low"},
    {"recording": "hem/depth", "camera_json": "cam.json", "fan": "low",
     "hem_mass": 0.3}
  ]}

Paths in the file are relative to the file's folder. ``"fabric"`` (optional)
holds the readings of the fabric itself, shared by every recording: a scale's
area weight and a cantilever test's bending length, each with its
uncertainty (``fabric_readings``; the flags of the same names otherwise); or,
instead of the bending length, a depth recording of the strip over a
table's edge that gives it (``fabric_overhang``)::

  "fabric": {"overhang": {"recording": "strip/depth",
                          "camera_json": "strip/camera.json",
                          "length": 0.05, "length_sd": 0.001}}
"""

from __future__ import annotations

import difflib
import json
import math
import os
from typing import NamedTuple

from physsim import input_files
from physsim.input_files import shown

# What a protocol file's entry may say (the rest is the estimate's flags).
KEYS = ('recording', 'camera_json', 'cloth_size', 'wind_speed', 'wind_speed_sd',
        'world_up', 'hem_mass', 'fan')  # fmt: skip
CLOTH_SIZE_RANGE = (0.05, 3.0)  # metres, as Simulation.cloth_size
HEM_MASS_RANGE = (0.0, 1.0)  # kg, as Simulation.hem_mass
UP_AXES = ('x', 'y', 'z', '-x', '-y', '-z')
# What a protocol file holds at its top level.
TOP_KEYS = ('recordings', 'fabric')
# The largest protocol file read (one of a hundred recordings takes 20 kB).
MAX_FILE_BYTES = 1 << 20


class Take(NamedTuple):
  """One recording and its own set-up.

  Attributes:
    path: the recording.
    camera_json: its camera file, or ''.
    cloth_size: the cloth's side, metres, or 0 (the estimate's --cloth_size).
    wind: an anemometer's reading at it, (m/s, its standard uncertainty), or
      None.
    world_up: its camera file's up axis, or '' (the intake's --world_up).
    hem_mass: kg taped along the cloth's free hem, or 0.
    fan: its fan setting's label, or '' (its own): recordings of one label
      share one wind.
  """

  path: str
  camera_json: str = ''
  cloth_size: float = 0.0
  wind: tuple[float, float] | None = None
  world_up: str = ''
  hem_mass: float = 0.0
  fan: str = ''


def _number(where: str, key: str, value, lo: float, hi: float) -> float:
  if isinstance(value, bool) or not isinstance(value, (int, float)):
    raise ValueError(f'{where}: "{key}" must be a number, got {shown(value)}')
  try:
    v = float(value)
  except OverflowError:  # an integer of hundreds of digits
    v = math.inf
  if not (math.isfinite(v) and lo <= v <= hi):
    raise ValueError(f'{where}: "{key}"={shown(value)} must be in [{lo}, {hi}]')
  return v


def check_keys(where: str, mapping: dict, known) -> None:
  """Refuses a key of ``mapping`` not in ``known``, naming it (and the known
  key it most likely misspells): a misspelt reading would be dropped.

  Raises:
    ValueError: naming ``where`` and the first unknown key.
  """
  unknown = [k for k in mapping if k not in known]
  if not unknown:
    return
  key = unknown[0]
  close = difflib.get_close_matches(key, known, 1, 0.5) if isinstance(key, str) else []
  hint = f' (did you mean "{close[0]}"?)' if close else ''
  more = f' and {len(unknown) - 1} more' if len(unknown) > 1 else ''
  raise ValueError(
    f'{where}: unknown key {shown(key, 40)}{more}{hint}; known: {", ".join(known)}'
  )


def _path(where: str, key: str, value, base: str, required: bool) -> str:
  """An entry's path, relative to the file's folder, checked to exist (and a
  camera file to be a regular file: a FIFO would block its reading)."""
  if not isinstance(value, str) or (required and not value):
    raise ValueError(f'{where}: "{key}" must be a path, got {shown(value)}')
  if len(value) > 4096 or '\0' in value:
    raise ValueError(f'{where}: "{key}" is no path ({shown(value)})')
  path = os.path.join(base, value) if value else ''
  if path and not os.path.exists(path):
    named = path if len(path) <= 200 else shown(path)
    raise ValueError(f'{where}: "{key}" {named}: no such file or folder')
  if path and key == 'camera_json':
    try:
      input_files.check_regular(path, 'camera file')
    except ValueError as e:
      raise ValueError(f'{where}: "{key}" {e}') from None
  if path and input_files.is_special(path):
    raise ValueError(f'{where}: "{key}" {path}: not a regular file or folder')
  return path


def _take(where: str, entry, base: str) -> Take:
  if not isinstance(entry, dict):
    raise ValueError(f'{where}: must be an object with "recording", got {shown(entry)}')
  check_keys(where, entry, KEYS)
  paths = {}
  for key in ('recording', 'camera_json'):
    paths[key] = _path(where, key, entry.get(key, ''), base, key == 'recording')
  size = 0.0
  if 'cloth_size' in entry:
    size = _number(where, 'cloth_size', entry['cloth_size'], *CLOTH_SIZE_RANGE)
  wind = None
  if 'wind_speed' in entry or 'wind_speed_sd' in entry:
    if not ('wind_speed' in entry and 'wind_speed_sd' in entry):
      raise ValueError(f'{where}: "wind_speed" and "wind_speed_sd" come together')
    wind = (
      _number(where, 'wind_speed', entry['wind_speed'], 0.0, 100.0),
      _number(where, 'wind_speed_sd', entry['wind_speed_sd'], 1e-9, 100.0),
    )
  up = entry.get('world_up', '')
  if not isinstance(up, str) or up not in ('', *UP_AXES):
    raise ValueError(
      f'{where}: "world_up"={shown(up)} must be one of {", ".join(UP_AXES)}'
    )
  hem = 0.0
  if 'hem_mass' in entry:
    hem = _number(where, 'hem_mass', entry['hem_mass'], *HEM_MASS_RANGE)
  fan = entry.get('fan', '')
  if not isinstance(fan, str) or len(fan) > 100:
    raise ValueError(
      f'{where}: "fan" must be a label (a string of at most 100), got {shown(fan)}'
    )
  return Take(paths['recording'], paths['camera_json'], size, wind, up, hem, fan)


def fans(recorded: list[Take]) -> list[str] | None:
  """Each take's fan setting (its own index where it names none), or None
  where no two share one."""
  labels = [t.fan or f'#{k}' for k, t in enumerate(recorded)]
  return labels if len(set(labels)) < len(labels) else None


# The fabric's own readings a protocol file may give, as (value, sd) pairs,
# with their ranges (kg/m^2, m).
FABRIC_KEYS = {'area_weight': (1e-3, 10.0), 'bending_length': (1e-4, 1.0)}


def _load(path: str) -> dict:
  """A protocol file's data (JSON, or YAML by its extension), its top-level
  keys checked.

  Raises:
    ValueError: naming the file: no regular file (a FIFO would block), too
      large, unreadable, a YAML alias (a few hundred bytes of them expand to
      gigabytes), not an object, or an unknown top-level key (a misspelt
      ``"fabric"`` would drop its readings).
  """
  if not os.path.lexists(path):
    raise ValueError(f'{path}: no such protocol file')
  text = input_files.read_text(path, 'protocol file', MAX_FILE_BYTES)
  if path.lower().endswith(('.yaml', '.yml')):
    try:
      data = input_files.load_yaml(text, path)
    except ValueError as e:
      raise ValueError(f'{input_files.short(e, 280)}') from None
  else:
    try:
      data = json.loads(text)
    except ValueError as e:
      raise ValueError(
        f'{path}: not a readable protocol file (JSON: {input_files.short(e, 120)})'
      ) from None
    except RecursionError:
      raise ValueError(
        f'{path}: not a readable protocol file (nested too deeply)'
      ) from None
  if not isinstance(data, dict):
    raise ValueError(
      f'{path}: not a readable protocol file: {shown(data, 40)}, not an object '
      '{"recordings": [...]}'
    )
  check_keys(path, data, TOP_KEYS)
  return data


def read(path: str) -> list[Take]:
  """The takes of a protocol file (JSON, or YAML by its extension).

  Raises:
    ValueError: an unreadable file, no recordings, or an entry that is not
      one (named by its index and key), before any recording is read.
  """
  data = _load(path)
  entries = data.get('recordings')
  if not isinstance(entries, list) or not entries:
    raise ValueError(f'{path}: needs "recordings": a list of one or more entries')
  base = os.path.dirname(os.path.abspath(path))
  out = [_take(f'{path}: recordings[{k}]', e, base) for k, e in enumerate(entries)]
  seen = {}
  for k, t in enumerate(out):
    real = os.path.realpath(t.path)
    if real in seen:
      raise ValueError(
        f'{path}: recordings[{k}] "recording" is recordings[{seen[real]}]\'s '
        f'({t.path if len(t.path) <= 120 else shown(t.path)}): one recording listed '
        'twice would count as two'
      )
    seen[real] = k
  for label in {t.fan for t in out if t.fan}:
    read = {t.wind for t in out if t.fan == label}
    if len(read) > 1:
      readings = sorted(read, key=str)
      raise ValueError(
        f'{path}: the recordings of fan {shown(label, 40)} were read '
        f'{shown(readings, 100)}: one wind, one reading (give it to each of them, '
        'or to none)'
      )
  return out


def fabric_readings(path: str) -> dict[str, float]:
  """The fabric's readings a protocol file gives (its ``"fabric"`` object:
  ``area_weight``, ``bending_length``, each with its ``_sd``, and the
  bending length's ``bending_length_dof`` when a depth camera read it), as
  the estimate's flat settings; {} where it gives none.

  Raises:
    ValueError: an unreadable file, an unknown key, a value out of range or a
      reading without its uncertainty (or the reverse), named.
  """
  data = _load(path)
  fabric = data.get('fabric', {})
  where = f'{path}: fabric'
  if not isinstance(fabric, dict):
    raise ValueError(f'{where}: must be an object of readings, got {shown(fabric)}')
  known = [k for name in FABRIC_KEYS for k in (name, f'{name}_sd')]
  known += ['bending_length_dof', 'overhang']
  check_keys(where, fabric, known)
  out = {}
  for name, (lo, hi) in FABRIC_KEYS.items():
    if (name in fabric) != (f'{name}_sd' in fabric):
      raise ValueError(f'{where}: "{name}" and "{name}_sd" come together')
    if name in fabric:
      out[name] = _number(where, name, fabric[name], lo, hi)
      out[f'{name}_sd'] = _number(where, f'{name}_sd', fabric[f'{name}_sd'], 1e-9, hi)
  if 'bending_length_dof' in fabric:  # a depth reading's t law (experiments.overhang)
    if 'bending_length' not in fabric:
      raise ValueError(f'{where}: "bending_length_dof" without "bending_length"')
    dof = _number(
      where, 'bending_length_dof', fabric['bending_length_dof'], 0.0, 1000.0
    )
    if 0 < dof <= 2:
      raise ValueError(
        f'{where}: "bending_length_dof"={dof}: 0 (Gaussian) or more than 2'
      )
    out['bending_length_dof'] = dof
  return out


OVERHANG_KEYS = ('recording', 'camera_json', 'length', 'length_sd', 'depth_scale')


class Overhang(NamedTuple):
  """A depth recording of the fabric's strip over a table's edge.

  Attributes:
    path: the recording.
    camera_json: its camera file.
    length: the strip's length past the edge, m.
    length_sd: its standard uncertainty, m (the strip's ruler marks).
    depth_scale: metres per unit of its 16-bit PNG frames.
  """

  path: str
  camera_json: str
  length: float
  length_sd: float = 0.001
  depth_scale: float = 0.001


def fabric_overhang(path: str) -> Overhang | None:
  """The overhang recording a protocol file's ``"fabric"`` gives, its paths
  relative to the file's folder; None where it gives none.

  Raises:
    ValueError: a missing file, an unknown key or a value out of range, named;
      a bending length given beside it.
  """
  data = _load(path)
  fabric = data.get('fabric', {})
  if not isinstance(fabric, dict) or 'overhang' not in fabric:
    return None
  where = f'{path}: fabric: overhang'
  entry = fabric['overhang']
  if 'bending_length' in fabric:
    raise ValueError(f'{where}: give it or "bending_length", not both')
  if not isinstance(entry, dict):
    raise ValueError(f'{where}: must be an object with "recording", got {shown(entry)}')
  check_keys(where, entry, OVERHANG_KEYS)
  base = os.path.dirname(os.path.abspath(path))
  paths = {}
  for key in ('recording', 'camera_json'):
    paths[key] = _path(where, key, entry.get(key), base, True)
  if 'length' not in entry:
    raise ValueError(f'{where}: needs "length", the strip past the edge, m')
  return Overhang(
    paths['recording'], paths['camera_json'],
    _number(where, 'length', entry['length'], 1e-3, 0.5),
    _number(where, 'length_sd', entry.get('length_sd', 0.001), 0.0, 0.05),
    _number(where, 'depth_scale', entry.get('depth_scale', 0.001), 1e-6, 1.0),
  )  # fmt: skip


def from_flags(
  recordings, camera_json: str = '', cloth_sizes=(), winds=None
) -> list[Take]:
  """The takes the flags describe: one camera file for all (or none), a
  cloth size per recording (or none: the estimate's), the wind readings of
  ``estimate.joint_winds``.

  Raises:
    ValueError: sizes for another number of recordings, or out of range.
  """
  n = len(recordings)
  if cloth_sizes and len(cloth_sizes) != n:
    raise ValueError(
      f'--cloth_sizes={",".join(map(str, cloth_sizes))}: need one size for each '
      f'of the {n} recordings'
    )
  for s in cloth_sizes:
    _number('--cloth_sizes', 'cloth_size', s, *CLOTH_SIZE_RANGE)
  sizes = list(cloth_sizes) or [0.0] * n
  winds = winds or [None] * n
  return [
    Take(p, camera_json, float(s), w)
    for p, s, w in zip(recordings, sizes, winds, strict=True)
  ]

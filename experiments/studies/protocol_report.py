"""The protocol study's result written: ``protocol.json`` (everything, the
slopes included), ``protocol_summary.json`` (without the slopes: small enough
to commit), and the narrowing table and mesh-convergence lines the command
line prints."""

from __future__ import annotations

import os

import numpy as np

from experiments.pipeline import files
from experiments.studies import protocol_bound

RESULT_FILE = 'protocol.json'
SUMMARY_FILE = 'protocol_summary.json'  # without the slopes: small enough to commit
FIGURE_FILE = 'protocol.png'


def geomean_range(table, label, mode, field):
  """(geometric mean, least, most) over the truths of the set ``label``'s
  narrowing of ``field`` (bending or area weight) in ``mode``."""
  v = np.array([e[mode][field] for e in table if e['set'] == label])
  return float(np.exp(np.log(v).mean())), float(v.min()), float(v.max())


def summary(result: dict) -> dict:
  """``result`` without its slopes, each set's and mesh pair's narrowing
  reduced to that of bending and area weight per mode."""
  out = {k: v for k, v in result.items() if k != 'slopes'}
  fields = ('bending', 'area_weight')
  out['table'] = [
    {k: (v if k not in protocol_bound.MODES else {f: v[f] for f in fields})
     for k, v in e.items()}
    for e in result['table']
  ]  # fmt: skip
  out['convergence'] = [
    {n: {m: r[m] for m in protocol_bound.MODES} for n, r in pair.items()}
    for pair in result['convergence']
  ]
  return out


def write(result: dict, workdir: str) -> None:
  """``result`` as ``RESULT_FILE`` and its ``summary`` as ``SUMMARY_FILE``,
  in ``workdir``."""
  files.write_json(os.path.join(workdir, RESULT_FILE), result)
  files.write_json(os.path.join(workdir, SUMMARY_FILE), summary(result))


def markdown(result: dict) -> str:
  """The narrowing table (geometric mean over truths, range in brackets)."""
  lines = ['| set | mode | bending | area weight |', '|---|---|---:|---:|']
  labels = list(dict.fromkeys(e['set'] for e in result['table']))
  for s in labels:
    for mode in protocol_bound.MODES:
      cells = []
      for field in ('bending', 'area_weight'):
        g, lo, hi = geomean_range(result['table'], s, mode, field)
        cells.append(f'{g:.2f} ({lo:.2f}-{hi:.2f})')
      lines.append(f'| {s} | {mode} | {cells[0]} | {cells[1]} |')
  return '\n'.join(lines)


def convergence_line(pair: dict) -> str:
  """One line: a candidate's narrowing (video; winds read) at two meshes."""
  parts = []
  for name, r in pair.items():
    parts.append(
      f'{name}: bending x{r["video"]["bending"]:.2f} '
      f'(winds read x{r["anemometer"]["bending"]:.2f}), '
      f'area weight x{r["video"]["area_weight"]:.2f} '
      f'(winds read x{r["anemometer"]["area_weight"]:.2f})'
    )
  return '; '.join(parts)

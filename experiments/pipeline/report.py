"""An estimate's tables as a person reads them, in at most ``WIDTH`` columns.

``report_table``: one estimate (what ``estimate`` and the demo print);
``distances_table``: one recording estimated by several distances side by
side; ``joint_table``: a joint estimate of several recordings of one fabric.
Each is a markdown table padded to read in a terminal too, with its notes
wrapped under it. The numbers come from ``summaries``, their names and units
from ``units``, the notes' words from ``table_notes``; what ``estimate``
prints beside a table is ``advice``'s, the pictures ``search_figures``'.
"""

from __future__ import annotations

import textwrap

import physsim
from experiments.pipeline import summaries, table_notes, units

WIDTH = 100  # columns the printed table and its notes fit in

# Each ``summaries.errors`` measure's name and how it prints: a factor ('x')
# or a percent.
_ERROR_NAMES = {
  'wind_speed_pct': ('wind', '%'),
  'area_weight_pct': ('area weight', '%'),
  'bending_factor': ('bending', 'x'),
  'load_ratio_pct': ('load ratio', '%'),
  'air_factor': ('air coefficient', 'x'),
}


def _markdown(head: list[str], rows: list[list[str]]) -> list[str]:
  """A markdown table whose columns are padded to their widest cell, so that
  it reads as a table in a terminal too."""
  widths = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
  line = lambda cells: (
    '| ' + ' | '.join(c.ljust(w) for c, w in zip(cells, widths, strict=True)) + ' |'
  )
  return [line(head), '|' + '|'.join('-' * (w + 2) for w in widths) + '|'] + [
    line(r) for r in rows
  ]


def notes(*paragraphs: str, width: int = WIDTH) -> list[str]:
  """Notes under a table, each wrapped to ``width`` columns."""
  return [
    line
    for p in paragraphs
    if p
    for line in textwrap.wrap(p, width, subsequent_indent='  ')
  ]


def _error_cell(key: str, v: float) -> str:
  """An error of ``errors``' ``key`` as a table prints it: a factor for
  bending, else percent."""
  return f'x{v:.2f}' if _ERROR_NAMES[key][1] == 'x' else f'{v:.1f}%'


def errors_table(errors: dict) -> list[str]:
  """The point's errors against the truth beside the range centre's, as a small
  table (percent; a factor for bending)."""
  rows = []
  for key, (name, _) in _ERROR_NAMES.items():
    if key not in errors['estimate']:
      continue
    rows.append(
      [name, _error_cell(key, errors['estimate'][key]),
       _error_cell(key, errors['range_centre'][key])]
    )  # fmt: skip
  return _markdown(['error against the truth', 'point', 'range centre'], rows)


def distances_table(results: dict[str, dict]) -> str:
  """Estimates of one recording by several distances, side by side: per
  quantity each one's point and 90% interval, the truth beside them, and
  each point's error against it (percent; a factor for bending)."""
  names = list(results)
  first = results[names[0]]
  truth = summaries.with_load_ratio(first['truth']) if first.get('truth') else {}
  label, unit = units.in_units(first.get('material'))
  rows = []
  for q in [*physsim.Params._fields, 'load_ratio']:
    k = unit[q]
    cells = [label[q]] + ([f'{k * truth[q]:.3g}'] if truth else [])
    for n in names:
      r = results[n]
      e = r['load_ratio'] if q == 'load_ratio' else r['estimate'][q]
      lo, hi = e['interval_90']
      cell = f'{k * e["value"]:.3g} [{k * lo:.3g}, {k * hi:.3g}]'
      if truth and 'errors' in r:
        key = 'bending_factor' if q == 'bending_scale' else f'{q}_pct'
        cell += f' ({_error_cell(key, r["errors"]["estimate"][key])})'
      cells.append(cell)
    rows.append(cells)
  head = ['quantity'] + (['true'] if truth else []) + names
  lines = _markdown(head, rows) + notes(
    'each: the point, [its 90% interval]'
    + (" and (the point's error against the truth)" if truth else '')
    + '; percent, a factor for bending.'
  )
  return '\n'.join(lines)


def report_table(result: dict) -> str:
  """An estimate for a person, in at most ``WIDTH`` columns: per quantity the
  point, its 50% and 90% credible intervals and how much narrower the 90% one
  is than the prior's (posterior), or the GP's interval (the paper's argmin);
  with ground truth the truth beside them and a small table of the point's
  errors against the range centre's; notes wrapped under it."""
  head = _estimate_head(result)
  rows = _estimate_rows(result)
  if length := _length_row(result, len(head)):
    rows.append(length)
  lines = _markdown(head, rows)
  if result.get('truth'):
    lines += [''] + errors_table(result['errors'])
  lines.append('')
  lines += notes(*table_notes.estimate_notes(result))
  return '\n'.join(lines)


def _is_posterior(result: dict) -> bool:
  """Whether an estimate has a posterior (else the paper's argmin and the GP)."""
  return result.get('point', 'argmin') != 'argmin'


def _estimate_head(result: dict) -> list[str]:
  """The estimate table's columns: the truth where known, the point and its
  intervals (a posterior's 50% and 90% and its narrowing, or the GP's 90%),
  and the network's retrieval where one was recorded."""
  head = ['quantity'] + (['true'] if result.get('truth') else [])
  if _is_posterior(result):
    head += ['point', '50% interval', '90% interval', 'narrower']
  else:
    head += ['point (argmin)', 'GP 90% interval']
  return head + (['retrieval'] if result.get('network_retrieval_vs_chance') else [])


def _estimate_rows(result: dict) -> list[list[str]]:
  """One row per parameter, the load ratio and an estimated air coefficient,
  in the unit a lab reads it: the truth ('-' where the truth does not know
  that quantity), the point, its intervals and the network's retrieval."""
  truth = result.get('truth')
  retrieval = result.get('network_retrieval_vs_chance', {})
  true = summaries.with_load_ratio(truth) if truth else {}
  label, unit = units.in_units(result.get('material'))
  air = ['air_coefficient'] if 'air_coefficient' in result['estimate'] else []
  rows = []
  for name in [*physsim.Params._fields, 'load_ratio', *air]:
    e = result['load_ratio'] if name == 'load_ratio' else result['estimate'][name]
    k = unit[name]
    cells = [label[name]] + (
      [f'{k * true[name]:.3g}' if name in true else '-'] if truth else []
    )
    cells += [f'{k * e["value"]:.3g}', *_interval_cells(e, k, _is_posterior(result))]
    if retrieval:
      cells += [f'{retrieval[name]:.2f}' if name in retrieval else '-']
    rows.append(cells)
  return rows


def _interval_cells(e: dict, k: float, posterior: bool) -> list[str]:
  """A quantity's interval cells, times the unit's factor ``k``: a
  posterior's 50% and 90% intervals and narrowing, or the GP's 90%."""
  iv = lambda key: f'[{k * e[key][0]:.3g}, {k * e[key][1]:.3g}]'
  if posterior:
    return [iv('interval_50'), iv('interval_90'), f'x{e["narrowing_90"]:.1f}']
  return [iv('interval_90')]


def _length_row(result: dict, columns: int) -> list[str] | None:
  """The point's bending length (and the truth's) as a lab reads it, '-' in
  the interval columns (it has no interval of its own); None where the
  fabric is not known (no reference rigidity)."""
  material, est = result.get('material'), result['estimate']
  length = units.length_mm(
    est['bending_scale']['value'], est['area_weight']['value'], material
  )
  if length is None:
    return None
  truth = result.get('truth')
  true_length = (
    [f'{units.length_mm(truth["bending_scale"], truth["area_weight"], material):.3g}']
    if truth
    else []
  )
  return [units.LENGTH_NAME, *true_length, f'{length:.3g}',
          *['-'] * (columns - 2 - len(true_length))]  # fmt: skip


def joint_table(joint: dict) -> str:
  """A joint estimate for a person, in at most ``WIDTH`` columns: shared
  bending and area weight and each recording's wind and load ratio (point,
  90% interval, narrowing), each beside the same recording estimated alone."""
  label, unit = units.in_units(joint.get('material'))
  iv = lambda e, k=1.0: (
    f'[{k * e["interval_90"][0]:.3g}, {k * e["interval_90"][1]:.3g}]'
  )
  rows = []
  air = ('air_coefficient',) if 'air_coefficient' in joint else ()
  for name in ('bending_scale', 'area_weight', *air):
    e, k = joint[name], unit[name]
    rows.append([f'{label[name]}, shared', f'{k * e["median"]:.3g}', iv(e, k),
                 f'x{e["narrowing_90"]:.1f}', '-', '-'])  # fmt: skip
  for i, r in enumerate(joint['recordings']):
    for name in ('wind_speed', 'load_ratio'):
      e, a = r[name], r['alone'].get(name)
      rows.append([
        f'{label[name]}, rec. {i}', f'{e["median"]:.3g}', iv(e),
        f'x{e["narrowing_90"]:.1f}', f'{a["value"]:.3g}' if a else '-',
        iv(a) if a else '-',
      ])  # fmt: skip
  head = ['quantity', 'point', '90% interval', 'narrower', 'alone', 'alone 90%']
  lines = _markdown(head, rows)
  shared = ('bending_scale', 'area_weight')
  alone = [
    [f'recording {i}']
    + [
      f'{unit[n] * r["alone"][n]["value"]:.3g} {iv(r["alone"][n], unit[n])}'
      for n in shared
    ]
    for i, r in enumerate(joint['recordings'])
  ]
  lines += [''] + _markdown(['each alone', *(label[n] for n in shared)], alone)
  lines += [''] + notes(*table_notes.joint_notes(joint))
  return '\n'.join(lines)

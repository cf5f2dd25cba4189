"""The tables' numbers: each estimate's errors recomputed, their means per
fabric or garment and method (the paper's Tables 2 and 3, beside the range
centre's and the paper's), the overall means and medians per method, and
both as markdown."""

from __future__ import annotations

import numpy as np

import physsim
from experiments.pipeline import eval_set, summaries

# The paper's PhySNet-depth results (percent error of wind speed, area weight).
PAPER = {
  'white_tablecloth': (6.5, 8.6),
  'gray_interlock': (9.6, 19.6),
  'black_denim': (5.4, 5.5),
  'ponte_roma': (35.0, 0.4),
  'sparkle_fleece': (34.6, 0.0),
  'red_violet': (16.7, 6.3),
  'pink_nylon': (12.6, 2.6),
  'tshirt': (3.1, 17.1),
  'shirt': (34.2, 1.5),
  'jeans': (21.7, 0.6),
}
ERRORS = ('wind_speed_pct', 'area_weight_pct', 'bending_factor', 'load_ratio_pct')
ERROR_NAMES = ('wind %', 'area weight %', 'bending factor', 'load ratio %')


def rescore(result: dict) -> dict:
  """The result with its ``errors`` recomputed by today's ``estimate.errors``
  from its estimate and truth (so older runs gain newer error measures)."""
  if 'truth' not in result or 'estimate' not in result:
    return result
  best = physsim.Params(
    *(result['estimate'][f]['value'] for f in physsim.Params._fields)
  )
  space = physsim.search_space(result['material'])
  return {**result, 'errors': summaries.errors(best, result['truth'], space)}


def _values(rows, source, err):
  return [r['errors'][source][err] for r in rows if err in r['errors'][source]]


def _mean(rows, source, err):
  vals = _values(rows, source, err)
  return summaries.mean_error(vals, err) if vals else float('nan')


def summarise(results: dict, methods) -> dict:
  """{(method, set name): {'n', 'failed', estimate/range_centre means}}."""
  groups = {}
  for (method, _, name, _), res in results.items():
    groups.setdefault((method, name), []).append(res)
  out = {}
  for (method, name), rows in sorted(groups.items()):
    ok = [r for r in rows if 'errors' in r]
    s = {'n': len(rows), 'failed': len(rows) - len(ok)}
    for source in ('estimate', 'range_centre'):
      s[source] = {e: _mean(ok, source, e) for e in ERRORS} if ok else None
    out[(method, name)] = s
  return out


def _group(key: tuple) -> str:
  return 'fabrics' if key[1] == 'fabrics' else 'garments'


def overall(results: dict, methods) -> dict:
  """Per method and group (fabrics, garments), over every recording: the mean
  and median of each error, and on how many recordings the method beats the
  range centre. ``('range centre', group)`` holds the trivial estimate's
  errors over the distinct recordings."""
  rows, centre = {}, {}
  for key, res in sorted(results.items()):
    if key[0] not in methods:
      continue
    rows.setdefault((key[0], _group(key)), []).append(res)
    if 'errors' in res:
      centre.setdefault(_group(key), {})[key[1:]] = res
  out = {}
  for (method, group), rs in rows.items():
    ok = [r for r in rs if 'errors' in r]
    s = {'n': len(rs), 'failed': len(rs) - len(ok)}
    for e in ERRORS:
      pairs = [
        (r['errors']['estimate'][e], r['errors']['range_centre'][e])
        for r in ok
        if e in r['errors']['estimate']
      ]
      s[e] = {
        'mean': _mean(ok, 'estimate', e),
        'median': float(np.median(_values(ok, 'estimate', e))) if pairs else None,
        'beats_centre': sum(a < b for a, b in pairs),
        'of': len(pairs),
      }
    out[(method, group)] = s
  for group, recs in centre.items():
    rs = list(recs.values())
    out[('range centre', group)] = {
      'n': len(rs),
      'failed': 0,
      **{
        e: {
          'mean': _mean(rs, 'range_centre', e),
          'median': float(np.median(_values(rs, 'range_centre', e))),
        }
        for e in ERRORS
      },
    }
  return out


def format_overall(table: dict) -> str:
  """Markdown of ``overall``: one row per method and group."""
  lines = [
    '### All recordings',
    '',
    '| method | set | n | '
    + ' | '.join(f'{n}: mean / median' for n in ERROR_NAMES)
    + ' | beats range centre on (wind / area weight / bending / load ratio) |',
    '|---' * (3 + len(ERRORS) + 1) + '|',
  ]
  for (method, group), s in sorted(
    table.items(), key=lambda kv: (kv[0][1], kv[0][0] == 'range centre', kv[0][0])
  ):
    num = lambda e, v: f'x{v:.2f}' if e == 'bending_factor' else f'{v:.1f}'
    cells = [
      num(e, s[e]['mean'])
      + ('' if s[e]['median'] is None else f' / {num(e, s[e]["median"])}')
      for e in ERRORS
    ]
    beats = (
      ' / '.join(f'{s[e]["beats_centre"]}' for e in ERRORS)
      + f' of {s[ERRORS[0]]["of"]}'
      if 'beats_centre' in s[ERRORS[0]]
      else ''
    )
    failed = f' ({s["failed"]} F)' if s['failed'] else ''
    lines.append(
      f'| {method} | {group} | {s["n"]}{failed} | '
      + ' | '.join(cells)
      + f' | {beats} |'
    )
  lines += [
    '',
    'Bending: geometric mean / median of the factor. Load ratio: rho v^2 / (w g) '
    'from the estimated wind and area weight against the true one (a static sheet '
    'constrains only this combination of the two).',
  ]
  return '\n'.join(lines)


def _fmt(s, source):
  if s[source] is None:
    return 'F | F | F'
  v = s[source]
  return (
    f'{v["wind_speed_pct"]:.1f} | {v["area_weight_pct"]:.1f} | '
    f'x{v["bending_factor"]:.2f}'
  )


def format_tables(summary: dict, methods) -> str:
  lines = []
  sets = (
    ('Table 2: fabrics', [f for f in physsim.FABRICS]),
    ('Table 3: garments', list(eval_set.GARMENT_FABRICS)),
  )
  for title, names in sets:
    names = [n for n in names if any((m, n) in summary for m in methods)]
    if not names:
      continue
    lines += [f'### {title}', '']
    head = '| | ' + ' | '.join(
      f'{m}: wind % | area weight % | bending factor' for m in methods
    )
    head += ' | range centre: wind % | area weight % | bending factor'
    head += ' | paper PhySNet-depth: wind % | area weight % |'
    lines.append(head)
    lines.append('|---' * (1 + 3 * len(methods) + 3 + 2) + '|')
    for n in names:
      cells = []
      centre = None
      for m in methods:
        s = summary.get((m, n))
        if s is None:
          cells.append('- | - | -')
          continue
        tag = f' ({s["failed"]}/{s["n"]} F)' if s['failed'] else ''
        cells.append(_fmt(s, 'estimate') + tag)
        centre = centre or (s if s['range_centre'] else None)
      pw, pa = PAPER.get(n, (float('nan'),) * 2)
      lines.append(
        f'| {n} | '
        + ' | '.join(cells)
        + f' | {_fmt(centre, "range_centre") if centre else "- | - | -"}'
        + f' | {pw} | {pa} |'
      )
    lines.append('')
  lines.append(
    "Mean over each fabric's or garment's recordings: percent error |est - true| / "
    'true of wind speed and area weight; bending as the factor exp|log(est / true)| '
    '(>= 1, geometric mean). "range centre" is the trivial estimate at the centre of '
    'the search box (log-centre for bending). F: every candidate blew up or the run '
    'failed.'
  )
  return '\n'.join(lines)

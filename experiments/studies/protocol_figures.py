"""The protocol study's figure: the narrowing of bending and area weight per
candidate set and mode, as bars (``protocol.png``)."""

from __future__ import annotations

import matplotlib
import matplotlib.ticker

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from experiments.pipeline import files  # noqa: E402
from experiments.studies import protocol_bound, protocol_report  # noqa: E402


def plot(result: dict, path: str) -> None:
  """Bars: narrowing per candidate set, bending and area weight, per mode
  (geometric mean over truths, whiskers their range)."""
  table = result['table']
  labels = list(dict.fromkeys(e['set'] for e in table))
  modes = protocol_bound.MODES
  fig, axes = plt.subplots(1, len(modes), figsize=(5 * len(modes), 0.35 * len(labels) + 2),
                           sharey=True)  # fmt: skip
  y = np.arange(len(labels))
  for ax, mode in zip(axes, modes, strict=True):
    for off, field, color in ((-0.2, 'bending', 'C0'), (0.2, 'area_weight', 'C1')):
      stats = np.array(
        [protocol_report.geomean_range(table, s, mode, field) for s in labels]
      )
      ax.barh(y + off, stats[:, 0], height=0.4, color=color, label=field.replace('_', ' '),
              xerr=np.maximum(0, [stats[:, 0] - stats[:, 1], stats[:, 2] - stats[:, 0]]),
              capsize=2)  # fmt: skip
    ax.axvline(1, color='k', lw=0.8)
    ax.set_xscale('log')
    ticks = [1, 1.5, 2, 3, 4, 6, 10, 20, 40]
    ax.set_xticks(ticks, [f'{t:g}' for t in ticks])
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_title({'video': 'video alone', 'anemometer': 'winds read to 2%',
                  'scale': 'area weight weighed to 2%'}[mode])  # fmt: skip
    ax.set_xlabel("prior's 90% width / posterior's")
  axes[0].set_yticks(y, labels)
  axes[0].invert_yaxis()
  axes[-1].legend(loc='lower left')
  b = ', '.join(f'{v:g}' for v in result['bendings'])
  fig.suptitle(f'{result["material"]}: Cramer-Rao narrowing of bending and area weight '
               f'(bending truths {b}; bars: geometric mean, whiskers: range)')  # fmt: skip
  fig.tight_layout()
  files.savefig(fig, path)
  plt.close(fig)

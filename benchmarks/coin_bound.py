"""How well a coin of known mass could read a fabric's area weight without a
scale: Fisher bounds of two recordings, before building a reader for either.

Issue 39 asks for the area weight to 4% without a scale. The sheet in a fan
reads it only through the air's force (the load ratio rho v^2 / (w g) with an
anemometer's v), and on another physics that force's model is what errs:
7.5% (BENCHMARKS.md). The one force a user can know without a scale or an
air model is a known weight: a coin (a 1 yen coin is 1.00 g, a euro cent
2.30 g, by their mints' specifications). Two ways to film it:

- **overhang**: taped under the free end of the overhang strip
  (``physsim.cantilever.Load``, the span it covers kept straight), the strip
  slid out until its tip points ``TIP_DEG`` down (set by eye). Its shape
  depends on L / c and on m / (w b c): with c from the strip without the coin
  (``PROTOCOL_RATIO`` bending lengths, read once or four times: both ends,
  face up and down, as ASTM D1388 reads them), w = m / (b q), q = m / (w b)
  from the coin's shape. The coin measures the rigidity D (m g L^2 / D sets
  the shape), so w = D / (g c^3) carries three times c's error;
- **hanging**: a strip of length ``HANG_LENGTH`` hung from two pins at one
  height ``HANG_SPAN`` of its length apart, the coin taped at its middle.
  Bending aside (c is a few cm of a 30 cm strip), it hangs as two catenary
  arcs meeting at the coin, whose shape depends on the coin's mass over the
  strip's, a = m / (w b l), alone (``hanging_curve``): w = m / (a b l), with
  the strip's length l and the pins' spacing each read to ``RULER_SD``
  (nuisances of the fit), no bending length needed.

The Fisher information of a profile about its parameters is its points'
normal displacements per unit of each, summed along it. Its one noise
constant is anchored on what the reader measures today: the plain
overhang's bound (three bending lengths, filmed at ``OVERHANG_DISTANCE``)
set to the reading's measured RMS error over the seed-1 set-ups
(``benchmarks/results/overhang_depth/seed1_protocol_sets.json``; that error
includes the strip's curl and thickness, so the constant is generous). A
profile's information grows with its length and, for a camera further away
(the hanging strip at ``HANG_DISTANCE``), falls as distance^-6 (points per
metre of strip as distance^-2, a depth camera's noise as distance^2). The
width b is read to ``RULER_SD`` of a ``WIDTH`` strip, the coin's mass known
to ``COIN_TOL``.

A Fisher bound is the error of an ideal reader with the anchored noise and
no model error (the coin's tape and place, the strip's bending and stretch
on the pins, its curl): a real reader errs more. It says which recording is
worth a reader.

  python -m benchmarks.coin_bound --out=$OUT/coin_bound
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np

import physsim
from experiments.pipeline import cli, files
from physsim import cantilever

WIDTH = 0.05  # m: the strip's width
RULER_SD = 0.0005  # m: a ruler's reading (width, length, the pins' spacing)
COIN_TOL = 0.005  # relative: a coin's mass about its specification
PROTOCOL_RATIO = 3.0  # the plain overhang's L / c (README, "How to record")
OVERHANG_DISTANCE = 0.45  # m: the overhang's camera (README)
TIP_DEG = 55.0  # the coin's overhang: its tip this far below the horizontal
HANG_LENGTH = 0.3  # m: the hanging strip
HANG_SPANS = (0.7, 0.9)  # the pins' spacing over its length
HANG_DISTANCE = 0.6  # m: its camera (the strip and both pins in view)
# (name, mass kg, diameter m): mints' specifications
COINS = (('1 yen', 0.00100, 0.0200), ('1 euro cent', 0.00230, 0.01625))
SCALES = (0.3, 1.0, 3.0)  # bending x the fabric's reference
ANCHOR = 'benchmarks/results/overhang_depth/seed1_protocol_sets.json'
_EPS = 1e-3  # central differences, in log units (or m for the spacing)


@dataclasses.dataclass(frozen=True)
class Args:
  """The bounds' settings.

  Attributes:
    anchor: a benchmarks.overhang_depth results file whose readings' RMS
      error of c anchors the noise.
    out: output folder (JSON, PNG).
  """

  anchor: str = ANCHOR
  out: str = 'out/coin_bound'


PRESETS = {'default': Args()}


def information(curves: np.ndarray, steps: np.ndarray, length: float) -> np.ndarray:
  """The (P, P) information, per unit of the noise constant, of a profile
  (``curves[0]``, (S, 2), m) about P parameters whose +-``steps`` moves give
  ``curves[1 + 2 p]`` and ``curves[2 + 2 p]``: the points' normal
  displacements per unit of each, averaged along the curve, times its
  ``length`` (m)."""
  base = curves[0]
  tangent = np.gradient(base, axis=0)
  tangent /= np.linalg.norm(tangent, axis=-1, keepdims=True)
  normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=-1)
  up, down = curves[1::2], curves[2::2]
  j = ((up - down) / (2 * steps[:, None, None]) * normal).sum(-1)  # (P, S)
  return length * (j @ j.T) / j.shape[1]


def overhang_curves(
  length: float, c: np.ndarray, q: np.ndarray, coin_d: float
) -> np.ndarray:
  """The strip's centre lines (K, S, 2), m: ``length`` over the edge,
  bending lengths ``c``, coins of mass-length ``q`` = m / (w b) (0: none;
  diameter ``coin_d``, flush with the free end)."""
  c, q = np.asarray(c, np.float64), np.asarray(q, np.float64)
  span = np.where(q > 0, coin_d / c, 0.0)
  load = cantilever.Load(mass=q / c, at=span / 2, span=span)
  return cantilever.shape(length / c, load) * length


def _steps_of(p: int, eps: float) -> np.ndarray:
  """Base, then +-eps along each of ``p`` parameters: (1 + 2 p, p) offsets."""
  out = [np.zeros(p)]
  for i in range(p):
    e = np.zeros(p)
    e[i] = eps
    out += [e, -e]
  return np.array(out)


def overhang_information(
  length: float, c: float, q: float, coin_d: float
) -> np.ndarray:
  """(2, 2) information about (log c, log q) of an overhang (q = 0: no coin;
  its log q row and column zero)."""
  off = _steps_of(2, _EPS)
  if not q:
    off[:, 1] = 0.0
  curves = overhang_curves(length, c * np.exp(off[:, 0]), q * np.exp(off[:, 1]), coin_d)
  info = information(curves, np.full(2, _EPS), length)
  if not q:
    info[1, :] = info[:, 1] = 0.0
  return info


def coin_overhang(c: float, q: float, coin_d: float, tip_deg: float) -> float | None:
  """The overhang (m) whose free end, under the coin, points ``tip_deg``
  below the horizontal (bisection between 1.2 coin diameters and
  ``PROTOCOL_RATIO`` bending lengths: longer hangs steeper); None where even
  the shortest hangs steeper (the coin too heavy for the fabric) or the
  longest not so steep."""

  def angle(length: float) -> float:
    try:
      line = overhang_curves(length, np.array([c]), np.array([q]), coin_d)[0]
    except ValueError:  # too nearly straight down to solve
      return 90.0
    d = line[-1] - line[-3]
    return math.degrees(math.atan2(d[1], d[0]))

  lo, hi = 1.2 * coin_d, max(PROTOCOL_RATIO * c, 1.3 * coin_d)
  if angle(lo) > tip_deg or angle(hi) < tip_deg:
    return None
  for _ in range(9):  # to 1/512 of the range: the bound hardly moves
    mid = (lo + hi) / 2
    lo, hi = (lo, mid) if angle(mid) > tip_deg else (mid, hi)
  return (lo + hi) / 2


def hanging_curve(a, span, samples: int = 201) -> np.ndarray:
  """(..., 2 samples - 1, 2): an inextensible strip of length 1 hung from two
  pins ``span`` apart at one height (0, 0) and (span, 0), a point mass of
  ``a`` times its own at its middle; (x, z) from one pin to the other.

  Each half is a catenary arc: with H the horizontal tension over the weight
  of the whole strip, the angle below the horizontal at arc length u from
  the middle has tan phi = (a / 2 + u) / H, so x(u) = H (asinh((a/2 + u) / H)
  - asinh(a / (2 H))) and the height likewise with sqrt(1 + (.)^2); H is
  the one that puts the pins ``span`` apart (bisection on log H).
  """
  a, span = np.broadcast_arrays(np.asarray(a, np.float64), np.asarray(span, np.float64))
  u = np.linspace(0.0, 0.5, samples)

  def half(h):
    t0 = a[..., None] / (2 * h[..., None])
    t = (a[..., None] / 2 + u) / h[..., None]
    x = h[..., None] * (np.arcsinh(t) - np.arcsinh(t0))
    z = h[..., None] * (np.sqrt(1 + t**2) - np.sqrt(1 + t0**2))
    return x, z

  lo, hi = np.full(a.shape, -12.0), np.full(a.shape, 12.0)  # log H
  for _ in range(80):
    mid = (lo + hi) / 2
    wide = 2 * half(np.exp(mid))[0][..., -1] > span
    lo, hi = np.where(wide, lo, mid), np.where(wide, mid, hi)
  x, z = half(np.exp((lo + hi) / 2))
  x_end, z_end = x[..., -1:], z[..., -1:]
  left = np.stack([x_end - x, z - z_end], -1)[..., ::-1, :]  # pin to middle
  right = np.stack([x_end + x, z - z_end], -1)[..., 1:, :]
  return np.concatenate([left, right], axis=-2)


def hanging_information(a: float, span: float, length: float) -> np.ndarray:
  """(3, 3) information about (log a, the pins' spacing (m), log l) of the
  hanging strip's profile: the spacing and length are the fit's nuisances."""
  off = _steps_of(3, _EPS)
  ls = length * np.exp(off[:, 2])
  curves = (
    hanging_curve(a * np.exp(off[:, 0]), (span * length + off[:, 1]) / ls)
    * ls[:, None, None]
  )
  return information(curves, np.full(3, _EPS), length)


def bound(c: float, w: float, coin: tuple, noise: float) -> dict:
  """Per design, the bound on w's relative error (sd of log w) for a fabric
  of bending length ``c`` and area weight ``w`` under ``coin``; ``noise``
  the anchored constant (variance per unit of information at
  ``OVERHANG_DISTANCE``)."""
  _, m, d = coin
  q = m / (w * WIDTH)
  out = {'c': c, 'w': w, 'coin_over_bending_length': q / c,
         'coin_over_strip': m / (w * WIDTH * HANG_LENGTH)}  # fmt: skip
  floor = COIN_TOL**2 + (RULER_SD / WIDTH) ** 2
  plain = overhang_information(PROTOCOL_RATIO * c, c, 0.0, 0.0) / noise
  out['plain c'] = math.sqrt(1.0 / plain[0, 0])
  far = (HANG_DISTANCE / OVERHANG_DISTANCE) ** 6
  for span in HANG_SPANS:
    info = hanging_information(out['coin_over_strip'], span, HANG_LENGTH) / (
      noise * far
    )
    info += np.diag([0.0, 1 / RULER_SD**2, (HANG_LENGTH / RULER_SD) ** 2])
    out[f'hanging, pins {span:g} l apart'] = math.sqrt(
      np.linalg.inv(info)[0, 0] + floor
    )
  length = coin_overhang(c, q, d, TIP_DEG)
  if length is None:
    out['overhang refused'] = f'no overhang points its tip {TIP_DEG:g} degrees down'
    return out
  coin_info = overhang_information(length, c, q, d) / noise
  out['coin_overhang'] = length
  for name, info in (
    ('overhang + coin', plain + coin_info),
    ('4 overhangs + coin', 4 * plain + coin_info),
    ('coin overhang, c exact', coin_info + np.diag([1e12, 0.0])),
  ):
    out[name] = math.sqrt(np.linalg.inv(info)[1, 1] + floor)
  return out


DESIGNS = ('overhang + coin', '4 overhangs + coin', 'coin overhang, c exact',
           *(f'hanging, pins {s:g} l apart' for s in HANG_SPANS))  # fmt: skip


def anchored_noise(path: str, cs: np.ndarray) -> tuple[float, float]:
  """(the noise constant, the RMS error it is anchored to): the constant
  whose plain-overhang bound, averaged as a variance over the bending lengths
  ``cs``, is the measured readings' mean squared relative error."""
  rows = physsim.dataset.read_json(path)['rows']
  err = np.array([r['error'] for r in rows if 'error' in r])
  rms = float(np.sqrt(np.mean(err**2)))
  inv = [1.0 / overhang_information(PROTOCOL_RATIO * c, c, 0.0, 0.0)[0, 0] for c in cs]
  return rms**2 / float(np.mean(inv)), rms


def cases() -> list[tuple[str, float, float, float]]:
  """(fabric, bending scale, area weight, bending length): each fabric at its
  box's central area weight and bending x``SCALES`` of its reference."""
  out = []
  for f in sorted(physsim.FABRICS):
    space = physsim.search_space(f)
    w = float(np.mean(space.area_weight))
    for s in SCALES:
      out.append((f, s, w, float(physsim.params.bending_length(s, w, space.rigidity))))
  return out


def summarise(rows: list[dict], rms: float, noise: float) -> dict:
  out = {'anchor_rms_c_error': rms, 'noise_constant': noise, 'cases': len(rows)}
  for d in DESIGNS:
    vals = [r[d] for r in rows if d in r]
    out[d] = {
      'cases': len(vals),
      'median_pct': 100 * float(np.median(vals)) if vals else None,
      'max_pct': 100 * float(np.max(vals)) if vals else None,
      'under_4pct': int(np.sum(np.array(vals) <= 0.04)),
    }
  return out


def table(rows: list[dict]) -> str:
  head = ['fabric', 'bending', 'c cm', 'coin', 'coin / bending length of strip',
          'coin / hanging strip', *(f'{d}: % sd of w' for d in DESIGNS)]  # fmt: skip
  lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
  for r in rows:
    cells = [r['fabric'], f'x{r["bending_scale"]:g}', f'{100 * r["c"]:.2f}', r['coin'],
             f'{r["coin_over_bending_length"]:.2g}', f'{r["coin_over_strip"]:.2g}',
             *(f'{100 * r[d]:.1f}' if d in r else 'too heavy' for d in DESIGNS)]  # fmt: skip
    lines.append('| ' + ' | '.join(cells) + ' |')
  return '\n'.join(lines)


def main(args: Args) -> None:
  todo = cases()
  noise, rms = anchored_noise(args.anchor, np.array([c for *_, c in todo]))
  rows = [
    {'fabric': f, 'bending_scale': s, 'coin': coin[0], **bound(c, w, coin, noise)}
    for f, s, w, c in todo
    for coin in COINS
  ]
  summary = summarise(rows, rms, noise)
  os.makedirs(args.out, exist_ok=True)
  files.write_json(os.path.join(args.out, 'coin_bound.json'),
                   {'args': dataclasses.asdict(args), 'summary': summary, 'rows': rows})  # fmt: skip
  plot(rows, os.path.join(args.out, 'coin_bound.png'))
  print(table(rows))
  print(json.dumps(summary, indent=1))


def plot(rows: list[dict], path: str) -> None:
  """The bound on w's error per design and coin: the overhangs against the
  fabric's bending length (an overhang the coin is too heavy for left out),
  the hanging strip against the coin's mass over the strip's (all its shape
  depends on)."""
  import matplotlib  # noqa: PLC0415

  matplotlib.use('Agg')
  import matplotlib.pyplot as plt  # noqa: PLC0415

  fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
  for k, d in enumerate(DESIGNS):
    hanging = d.startswith('hanging')
    ax, x = (axes[1], 'coin_over_strip') if hanging else (axes[0], 'c')
    scale = 1.0 if hanging else 100.0
    for j, (name, *_) in enumerate(COINS):
      mine = sorted(
        (r for r in rows if r['coin'] == name and d in r), key=lambda r: r[x]
      )
      ax.plot([scale * r[x] for r in mine], [100 * r[d] for r in mine],
              'os'[j] + ('-', ':')[j], color=f'C{k}', ms=4, lw=1,
              label=f'{d}, {name}')  # fmt: skip
  for ax, xlabel in zip(
    axes,
    ("the fabric's bending length c (cm)", "the coin's mass over the hanging strip's"),
    strict=True,
  ):
    ax.axhline(4.0, color='k', lw=0.8, ls='--')
    ax.text(0.99, 4.1, "issue 39's 4%", fontsize=7, va='bottom', ha='right',
            transform=ax.get_yaxis_transform())  # fmt: skip
    ax.set_yscale('log')
    ax.set_xlabel(xlabel)
    ax.legend(fontsize=6, loc='upper right')
  axes[0].set_ylabel("bound on the area weight's error (% sd)")
  axes[0].set_title('a coin under the overhang strip (too heavy: left out)', fontsize=9)
  axes[1].set_title(f'a coin at the middle of a {100 * HANG_LENGTH:g} cm strip hung from two pins',
                    fontsize=9)  # fmt: skip
  fig.suptitle('area weight from a coin of known mass: Fisher bounds (an ideal reader)',
               fontsize=10)  # fmt: skip
  fig.tight_layout()
  files.savefig(fig, path, dpi=110)
  plt.close(fig)


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)

"""The real-like evaluation set: seven fabrics and three garments with ground truth.

The paper's recordings are not public, so we make recordings that differ from
the training data the way reality does (``generate_dataset``'s ``eval``
preset: finer mesh, depth-sensor noise, 24 fps for 2.5 s, camera poses the
training set never used, gustier wind, one camera) and keep their ground truth.
Each recording also has colour frames (``cam0/rgb_*.png``, the fabric's colour,
no noise), so one set serves the depth and the RGB methods.
Garments follow the paper: a T-shirt of interlock, a shirt of tablecloth and
jeans of denim, each later estimated with the network of its fabric.

``experiments/make_eval_set.py`` is its command line.

Layout: ``<out>/fabrics`` (all seven) and ``<out>/<garment>``, each a
``physsim.dataset`` root; reruns resume.
"""

from __future__ import annotations

import dataclasses

from experiments.pipeline import datasets as gen

# The paper's garments and the fabric each is made of.
GARMENT_FABRICS = {
  'tshirt': 'gray_interlock',
  'shirt': 'white_tablecloth',
  'jeans': 'black_denim',
}


def configs(smoke: bool = False, **overrides) -> dict[str, gen.Config]:
  """Subfolder name -> dataset config of the evaluation set."""
  base = dataclasses.replace(gen.PRESETS['eval'], rgb=True)
  if smoke:
    base = dataclasses.replace(
      base,
      sequences=1,
      batch_size=1,
      frames=12,
      warmup=0.5,
      cloth_resolution=12,
      resolution=64,
      backend='c',
      workers=1,
    )
  base = dataclasses.replace(base, **{k: v for k, v in overrides.items() if v})
  out = {
    'fabrics': dataclasses.replace(
      base, materials=('gray_interlock', 'black_denim') if smoke else base.materials
    )
  }
  for garment, fabric in list(GARMENT_FABRICS.items())[: 1 if smoke else None]:
    out[garment] = dataclasses.replace(
      base,
      materials=(fabric,),
      garment=garment,
      garment_spacing=0.08 if smoke else 0.03,
    )
  return out


def run(out: str, smoke: bool = False, **overrides) -> dict[str, dict]:
  """Generates (or resumes) every part of the evaluation set under ``out``.

  Args:
    out: the set's root.
    smoke: the tiny CPU version.
    **overrides: ``datasets.Config`` fields applied to every part (falsy
      values ignored: 0 means "the preset's").

  Returns:
    Part name -> its ``datasets.run`` summary.
  """
  summaries = {}
  for name, config in configs(smoke, **overrides).items():
    if config.sequences and config.batch_size > config.sequences:
      config = dataclasses.replace(config, batch_size=config.sequences)
    print(f'== {name}', flush=True)
    summaries[name] = gen.run(config, f'{out}/{name}')
  return summaries

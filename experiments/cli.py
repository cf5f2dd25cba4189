"""Flags shared by the preset-driven study scripts (``--workdir``, ``--preset``,
``--backend``), defined only when a script runs: a module that defines flags on
import takes names that other scripts' ``define_flags`` check for."""

from __future__ import annotations

import dataclasses

from absl import app, flags

FLAGS = flags.FLAGS


def define_preset_flags(workdir: str, presets: dict) -> None:
  """``--workdir`` (default ``workdir``), ``--preset`` (a key of ``presets``,
  default the first) and ``--backend`` (overrides the preset's)."""
  flags.DEFINE_string('workdir', workdir, 'results and figures')
  flags.DEFINE_enum('preset', next(iter(presets)), list(presets), 'sizes')
  flags.DEFINE_enum(
    'backend', None, ['auto', 'mjx', 'c'], "override: 'auto' = MJX on GPU"
  )


def preset_config(presets: dict):
  """The chosen preset's config, with ``--backend`` applied."""
  config = presets[FLAGS.preset]
  if FLAGS.backend:
    config = dataclasses.replace(config, backend=FLAGS.backend)
  return config


def run_script(presets: dict, run, workdir: str) -> None:
  """Defines the flags and runs ``run(config, workdir)`` with the chosen
  preset: a study script's whole ``__main__``."""
  define_preset_flags(workdir, presets)

  def main(argv):
    del argv
    run(preset_config(presets), FLAGS.workdir)  # not returned: app.run exits with it

  app.run(main)

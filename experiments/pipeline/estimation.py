"""The estimate, end to end: the library's entry point.

The last of the estimate's stages, in the order they run: a recording in
(``recording``, ``intake``), what is known before the video
(``measurements``), the objective (``objective``: simulate, render, score),
the search (``search``), the posterior (``posterior``), and what a person
reads (``report``, ``results``), one recording alone or several of one
fabric (``joint``). Each stage imports only the stages before it.

  from experiments.pipeline import estimation
  result = estimation.estimate(config, recording, model_dir, workdir)
  results = estimation.estimate_many([search.Job(config, recording, model_dir, workdir)])
  joint = estimation.estimate_joint(config, [rec_a, rec_b], model_dir, workdir)
"""

from __future__ import annotations

import functools

from experiments.pipeline import embedding, joint, results, search
from experiments.pipeline import setup as setup_lib
from experiments.pipeline.evaluation import Evaluator
from experiments.pipeline.objective import EstimateConfig
from experiments.pipeline.recording import Recording
from experiments.pipeline.searcher import Job


def estimate(
  config: EstimateConfig,
  recording: Recording,
  model_dir: str,
  workdir: str,
  *,
  progress: bool = True,
  gp_on_cpu: bool = True,
  evaluator: Evaluator | None = None,
  allow_other_material: bool = False,
  nets: dict[str, embedding.EmbeddingNet] | None = None,
  setup: setup_lib.Setup | None = None,
  pictures: list | None = None,
) -> dict:
  """Runs (or resumes) one estimate; returns and writes ``estimate.json``.

  Args:
    config: settings.
    recording: the video (``load_recording``; with ``rgb=True`` for an RGB
      network).
    model_dir: a trained run of this material's network (PhySNet or SDN,
      depth or RGB); '' with ``distance='shape'``, which needs none.
    workdir: where state, JSON and pictures go.
    progress: print one line per iteration.
    gp_on_cpu: fit the GP and propose on the CPU (``gp_device``).
    evaluator: an ``Evaluator`` to reuse (its compiled objectives) across
      estimates in one process; default a new one.
    allow_other_material: search with a network of other fabrics.
    nets: the network already restored, by ``model_dir`` (not restored again).
    setup: ``setup.resolve(config, model_dir)`` if the caller has it (nothing
      is read again); its settings must be ``config``'s.
    pictures: a list to put the pictures' drawing in, for the caller to run
      after it printed the answer (``estimate_many``); None: drawn here.

  Returns:
    The result dict written to ``estimate.json``.

  Raises:
    ValueError: ``model_dir`` is not a trained run, was trained on another
      fabric, or takes another frame size, an RGB network and a recording
      without colour frames, a recording shorter than an SDN clip, ``workdir`` holds an estimate of another
      recording, camera, model or config, or every candidate simulation blew
      up (naming the recording).
  """
  if setup is not None:
    mine, theirs = config.flat(), setup.config.flat()
    if mine != theirs:
      raise ValueError(
        'the setup was resolved for other settings than the estimate is given: '
        + ', '.join(
          sorted(k for k in mine.keys() | theirs.keys() if mine.get(k) != theirs.get(k))
        )  # fmt: skip
      )
  (out,) = estimate_many(
    [Job(config, recording, model_dir, workdir, allow_other_material, setup)],
    progress=progress, gp_on_cpu=gp_on_cpu, evaluator=evaluator, nets=nets,
    pictures=pictures,
  )  # fmt: skip
  if isinstance(out, Exception):
    raise out
  return out


def estimate_many(
  jobs: list[Job],
  *,
  progress: bool = True,
  gp_on_cpu: bool = True,
  nets: dict[str, embedding.EmbeddingNet] | None = None,
  evaluator: Evaluator | None = None,
  figures: bool = True,
  pictures: list | None = None,
) -> list[dict | Exception]:
  """Runs (or resumes) every job's estimate, scoring their candidates together
  (``search.run``), each finished search written by ``results.write_result``.

  Args:
    jobs: the recordings.
    progress: print one line per step.
    gp_on_cpu: fit the GPs and propose on the CPU.
    nets: networks the caller has loaded already, by ``model_dir``.
    evaluator: an ``Evaluator`` to reuse across calls (default a new one).
    figures: draw each estimate's pictures (a study of hundreds may not want them).
    pictures: a list to put the pictures' drawing in (callables, for the
      caller to run once it has printed the answer: the table first, the
      pictures after); None: drawn as each estimate is written.

  Returns:
    Per job, its ``estimate.json`` dict, or the exception that stopped it
    (``search.run``).

  Raises:
    deadline.Reached: ``search.run``'s; the same call resumes.
  """
  write = functools.partial(results.write_result, figures=figures, pictures=pictures)
  return search.run(
    jobs, write, progress=progress, gp_on_cpu=gp_on_cpu, nets=nets,
    evaluator=evaluator,
  )  # fmt: skip


def estimate_joint(
  config: EstimateConfig,
  recordings: list[Recording],
  model_dir: str,
  workdir: str,
  winds: list[tuple[float, float]] | None = None,
  allow_other_material: bool = False,
  overrides: list[dict] | None = None,
  fans: list[str] | None = None,
  **kw,
) -> dict:
  """One fabric seen in several recordings (e.g. two fan settings): a joint
  posterior with one bending and area weight and one wind per recording.

  Each recording gets its own posterior search (in lockstep, under
  ``<workdir>/recording_<k>``); their likelihoods on the shared grid are then
  multiplied over bending and area weight, each recording's wind integrated
  out (``posterior.joint``). Writes ``joint.json`` and ``joint.png``. Many
  fabrics at once: ``joint_jobs`` for each, one ``estimate_many`` over all
  their jobs, then ``combine_joint`` for each.

  Args:
    config: settings (``point='median'`` or ``'bayes'``; a measured area
      weight applies to all recordings; a measured wind cannot, as each
      recording has its own: see ``winds``).
    recordings: two or more recordings of the same fabric.
    model_dir: the fabric's trained network ('' for none: ``estimate``).
    workdir: where everything goes.
    winds: an anemometer's reading at each recording, ``(m/s, its standard
      uncertainty)`` in the recordings' order, or None. Each enters that
      recording's search as its prior (its simulations go to that slice) and
      the joint posterior through it. Its intervals are recalibrated where
      the calibration has tables for the mode 'joint pair, known winds' (the
      shipped one has none: they are reported as indicative).
    allow_other_material: search with a network of other fabrics.
    overrides: per recording, the settings that are its own
      (``PER_RECORDING``: its cloth's size and mesh, a known mass at its hem,
      its camera's error), or None; a sheet and a swatch of one fabric share
      one posterior this way.
    fans: per recording, its fan setting's label: recordings of one label
      share one wind (``posterior.joint``), and must have one reading of it
      or none; None: one wind each.
    **kw: ``estimate_many``'s keywords (``nets`` goes to ``joint_jobs``).

  Returns:
    The dict written to ``joint.json``: per recording its own estimate and its
    wind and load ratio under the joint posterior, and the shared bending and
    area weight.

  Raises:
    ValueError: fewer than two recordings, ``point='argmin'``, a measured
      wind in ``config``, readings or fans for another number of recordings,
      two readings of one fan setting, a reading the search box cannot
      hold, or a recording whose estimate failed (named).
  """
  jobs = joint.joint_jobs(
    config, recordings, model_dir, workdir, winds, allow_other_material, overrides,
    nets=kw.pop('nets', None), fans=fans,
  )  # fmt: skip
  return joint.combine_joint(jobs, estimate_many(jobs, **kw), workdir, fans)

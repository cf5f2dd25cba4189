"""What an estimate is built from, resolved once at the edge.

A command line or a library user names settings and a network's folder; the
pipeline needs values: the network and what it was trained on, how it was
made (recipe, held-out accuracy, retrieval), the rest mesh and the midpoint
of its pins, the search box, and the calibration tables that match these
settings. ``resolve`` reads each of them once and checks them together (the
settings, a network of another fabric, a distance that needs a network), so
that the objective, the search and the report take these values instead of
re-reading config fields and folders.

  from experiments.pipeline import objective, setup
  s = setup.resolve(objective.PRESETS['smoke'], model_dir)
  s.network.embedding.image_size   # the frames it compares
  s.calibration                     # calibration_tables.calibration_note of these settings
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

import physsim
from experiments.pipeline import (
  calibration_tables,
  carried_errors,
  embedding,
  measurements,
  protocol_checks,
)
from experiments.pipeline import objective as obj_lib


class Network(NamedTuple):
  """The network an estimate compares frames through, and how it was made.

  Attributes:
    model_dir: its folder ('' for none: the shape distance; several members
      of an ensemble joined by commas).
    embedding: the loaded network (``embedding.EmbeddingNet``).
    recipe: ``embedding.network_recipe`` (None without a network).
    accuracy: its held-out triplet accuracy, if recorded.
    retrieval: its parameter retrieval over chance, if recorded.
  """

  model_dir: str
  embedding: embedding.EmbeddingNet
  recipe: dict | None
  accuracy: float | None
  retrieval: dict[str, float] | None


class Setup(NamedTuple):
  """Everything an estimate of one fabric needs besides its recordings.

  Attributes:
    config: the checked settings.
    network: the network and its record (``Network``).
    mesh: the rest mesh simulated (``objective.mesh``).
    pin_centre: (3,) the midpoint of its pinned vertices, where a camera's
      placement error turns about.
    space: the fabric's search box.
    calibration: ``calibration_tables.calibration_note`` of these settings, network and
      mode (None where no calibration is shipped).
    widened: what widened the fabric's box to ``space`` (a reading outside
      it: ``measurements.search_box``), a line each.
  """

  config: obj_lib.EstimateConfig
  network: Network
  mesh: physsim.Mesh
  pin_centre: np.ndarray
  space: physsim.SearchSpace
  calibration: dict | None
  widened: tuple[str, ...] = ()


def check_material(net: Network, material: str, allow_other: bool = False) -> None:
  """Refuses a network trained on other fabrics than ``material`` (unless
  ``allow_other``), naming its folder and both fabrics: the one rule of the
  command line and the library.

  Raises:
    ValueError: ``material`` is not among the network's fabrics.
  """
  trained = net.embedding.materials
  if trained and material not in trained and not allow_other:
    raise ValueError(
      f'{net.model_dir} was trained on {list(trained)}, not {material}; pass '
      '--allow_other_material to search with it anyway'
    )


def record(model_dir: str, loaded: embedding.EmbeddingNet | None = None) -> Network:
  """The trained run at ``model_dir`` (``loaded`` if the caller has restored
  it already) with its recipe, accuracy and retrieval, each read once."""
  return Network(
    model_dir,
    loaded if loaded is not None else embedding.load_embedding(model_dir),
    embedding.network_recipe(model_dir),
    embedding.network_accuracy(model_dir),
    embedding.network_retrieval(model_dir),
  )


def network(
  model_dir: str,
  distance: str,
  image_size: int,
  material: str,
  *,
  allow_other_material: bool = False,
) -> Network:
  """The network for ``distance`` (``embedding.for_distance``) with its record.

  Raises:
    ValueError: no network for a distance that embeds, an image size out of
      range, or a network trained on other fabrics than ``material`` (unless
      ``allow_other_material``), naming the folder and both fabrics.
  """
  net = embedding.for_distance(model_dir, distance, image_size)
  out = record(model_dir, net) if model_dir else Network('', net, None, None, None)
  check_material(out, material, allow_other_material)
  return out


def calibration(
  config: obj_lib.EstimateConfig,
  net: Network,
  *,
  joint: bool = False,
  recordings: int = 1,
  uncalibrated: tuple[str, ...] = (),
  every_wind_read: bool = False,
  cameras: tuple[tuple[float, float], ...] = (),
) -> dict | None:
  """``calibration_tables.calibration_note`` of these settings, this network's recipe and
  accuracy, and the mode (a joint estimate of ``recordings`` recordings;
  ``uncalibrated``: what else about it no calibration has measured;
  ``every_wind_read``: each of them with its own anemometer reading;
  ``cameras``: each recording's own camera error, (metres, degrees), where
  they differ: one check or one table must cover them all)."""
  variants = [config.replace(camera_sd_m=m, camera_sd_deg=d) for m, d in cameras]
  variants = variants or [config]
  if joint and every_wind_read and not uncalibrated:
    found = _protocol_note(variants, recordings, cameras)
    if found is not None:
      return found
  notes = [
    calibration_tables.calibration_note(
      v,
      joint=joint,
      recordings=recordings,
      network=net.recipe,
      accuracy=net.accuracy,
      uncalibrated=uncalibrated,
    )
    for v in variants
  ]
  if None in notes or len(notes) == 1:
    return notes[0]
  if missed := next((n for n in notes if not n['matches']), None):
    return missed  # a recording's camera error no table covers: named
  if len({n['setting'] for n in notes}) > 1 and (common := _common_table(variants)):
    notes = [  # each nearest another's, but one table covers them all
      calibration_tables.calibration_note(
        v.replace(calibration=common), joint=joint, recordings=recordings,
        network=net.recipe, accuracy=net.accuracy, uncalibrated=uncalibrated,
      )
      for v in variants
    ]  # fmt: skip
  if len({n['setting'] for n in notes}) > 1:
    return _cameras_apart(notes[0], cameras, 'table')
  return notes[0]


def _cameras_apart(note: dict, cameras, what: str) -> dict:
  """The note of a joint whose recordings' camera errors (``cameras``) no one
  ``what`` (a table, a protocol check) covers, headed as ``note`` (the
  first recording's)."""
  words = ', '.join(carried_errors.camera_words(c) for c in cameras)
  return {
    **{k: note[k] for k in ('n', 'setting', 'likelihood', 'sharpness') if k in note},
    'matches': False,
    'differs': [f'camera alignment errors of the recordings ({words}) '
                f'within no one {what}'],
  }  # fmt: skip


def _protocol_note(variants, recordings: int, cameras) -> dict | None:
  """A protocol joint's note (``protocol_checks``): the shipped check that
  covers every recording (``variants``: each with its own camera error), or
  what keeps the nearest check from the first it does not cover; None where
  it is no protocol joint (the tables' note then)."""
  found = [protocol_checks.protocol_note(v, recordings) for v in variants]
  if all(found) and len({f['setting'] for f in found}) == 1:
    return found[0]
  if all(found):
    return _cameras_apart(found[0], cameras, 'protocol check')
  first = next(v for v, f in zip(variants, found, strict=True) if not f)
  return protocol_checks.protocol_miss(first, recordings)


def _common_table(variants) -> str | None:
  """The shipped calibration whose tables cover every one of ``variants``
  (each recording's settings, its own camera error), the one whose
  recordings' errors were most like theirs (``carried_errors.recordings_gap``);
  None where none does."""
  shipped = calibration_tables.shipped_calibrations(variants[0].scoring.distance)
  fits = []
  for path in shipped:
    cal = calibration_tables.read_calibration(path)
    if not any(calibration_tables.differing_fields(v, cal) for v in variants):
      table = carried_errors.table_of(cal)
      gap = sum(
        carried_errors.recordings_gap(table, carried_errors.camera_of(v.flat()))
        for v in variants
      )  # fmt: skip
      fits.append((gap, path))
  return min(fits)[1] if fits else None


def resolve(
  config: obj_lib.EstimateConfig,
  model_dir: str = '',
  *,
  image_size: int = 64,
  allow_other_material: bool = False,
  joint: bool = False,
  recordings: int = 1,
  network_record: Network | None = None,
) -> Setup:
  """Checks ``config`` and reads what an estimate with it is built from, once.

  Args:
    config: the estimate's settings.
    model_dir: the fabric's trained network ('' for none: ``--distance=shape``).
    image_size: pixels a side the frames are compared at without a network.
    allow_other_material: accept a network trained on other fabrics.
    joint, recordings: a joint estimate of that many recordings (the
      calibration's mode depends on it).
    network_record: the network as the caller has read it already (``record``
      or ``network``): not read again, only checked against the fabric.

  Raises:
    ValueError: a setting out of range (``EstimateConfig.check``) or a network
      that does not fit (``network``).
  """
  config.check()
  if network_record is None:
    net = network(
      model_dir, config.scoring.distance, image_size, config.simulation.material,
      allow_other_material=allow_other_material,
    )  # fmt: skip
  else:
    net = network_record
    check_material(net, config.simulation.material, allow_other_material)
  mesh = obj_lib.mesh(config.simulation)
  space, widened = search_box(config)
  return Setup(
    config=config,
    network=net,
    mesh=mesh,
    pin_centre=mesh.vertices[mesh.pinned].mean(0),
    space=space,
    calibration=calibration(
      config, net, joint=joint, recordings=recordings, uncalibrated=_box_words(widened)
    ),
    widened=tuple(widened),
  )


def search_box(config: obj_lib.EstimateConfig):
  """The estimate's search space (``measurements.search_box``: widened to
  hold its readings, or the one ``--box`` set) and what widened it."""
  space, widened = measurements.search_box(
    config.simulation.material, config.measured, config.search.box
  )
  if config.search.box and tuple(config.search.box) != tuple(
    physsim.search_space(config.simulation.material).bounds().ravel()
  ):
    widened = [f'search box set to {tuple(config.search.box)} (--box)']
  return space, widened


def estimate_note(
  config: obj_lib.EstimateConfig, net: Network, *, joint: bool = False,
  recordings: int = 1,
) -> dict | None:  # fmt: skip
  """The calibration note an estimate with ``config`` and ``net`` prints
  (``calibration``), a search box other than the fabric's named among
  what no calibration measured."""
  return calibration(
    config, net, joint=joint, recordings=recordings,
    uncalibrated=_box_words(search_box(config)[1]),
  )  # fmt: skip


def _box_words(widened) -> tuple[str, ...]:
  """What no calibration measured about a search box that ``widened`` says
  is not the fabric's own (``search_box``)."""
  return ("a search box other than the fabric's",) if widened else ()

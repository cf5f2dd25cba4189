"""physsim: MuJoCo flex cloth in ArcSim-style wind, batched on MuJoCo Warp (MJX's engine).

Public API::

  mesh = physsim.square(25)                       # or physsim.garment('tshirt')
  model = physsim.build(mesh, 'gray_interlock')   # compiled cloth
  p = physsim.params.make(bending_scale=[1, 3], wind_speed=[3, 4], area_weight=[.18, .2])
  out = physsim.simulate(model, p, wind=physsim.Wind(gust_intensity=0.2), key=key)
  out.positions  # (B, T, V, 3); out.valid: (B,)
  poses = jax.vmap(lambda k: physsim.sample_poses(k, 6))(keys)  # (B, 6) cameras
  render = physsim.make_depth_renderer(mesh.faces, physsim.Intrinsics())
  depth = render(out.positions, poses)           # (B, C, T, H, W) metres, 0 = none

  ds = physsim.dataset.open_dataset('data/sim')   # 16-bit mm PNG sequences
  v = physsim.load_depth_video('capture/', source_fps=24)  # real depth video
  r = physsim.overhang_depth.read_recording('strip/', 'camera.json', 0.05)
  r.bending_length, r.bending_length_sd          # a strip over a table's edge
  mesh = physsim.devices.world_mesh()             # worlds split over local devices
"""

from physsim import (
  camera,
  cantilever,
  dataset,
  devices,
  interrupt,
  mismatch,
  motion,
  one_off,
  overhang_depth,
  params,
  render,
  sensor,
  shape,
  tabletop,
  video,
)
from physsim.camera import (
  Intrinsics,
  Pose,
  PoseRanges,
  look_at,
  pose_from_dict,
  pose_to_dict,
  sample_poses,
  world_to_camera,
)
from physsim.cloth import (
  EDGE_SOLREF_SPACING,
  ClothModel,
  SimConfig,
  build,
  config_for_mesh,
  hem_mass,
  reference_rigidity,
  scaled_edge_solref,
  stable_timestep,
)
from physsim.forces import Gusts, face_wind_forces, sample_gusts
from physsim.materials import FABRICS, Fabric, Material, fabric, load_material
from physsim.mesh import GARMENTS, Mesh, garment, square
from physsim.mismatch import MISMATCHES, Mismatch
from physsim.params import (
  Params,
  SearchSpace,
  from_unit,
  load_ratio,
  search_space,
  to_unit,
)
from physsim.render import (
  FABRIC_COLORS,
  depth_image,
  make_depth_renderer,
  render_depth,
  render_rgb,
  render_rgb8,
  shade_rgb,
)
from physsim.rollout import (
  BACKENDS,
  Rollout,
  Wind,
  WorldInputs,
  resolve_backend,
  rollout_fn,
  simulate,
  world_inputs,
)
from physsim.sensor import SensorNoise, apply_noise, apply_noise_frames
from physsim.video import DepthVideo, load_depth_video

__all__ = [
  'FABRICS',
  'FABRIC_COLORS',
  'GARMENTS',
  'MISMATCHES',
  'ClothModel',
  'DepthVideo',
  'Fabric',
  'Gusts',
  'Intrinsics',
  'Material',
  'Mesh',
  'Mismatch',
  'Params',
  'Pose',
  'PoseRanges',
  'Rollout',
  'SearchSpace',
  'SensorNoise',
  'SimConfig',
  'Wind',
  'WorldInputs',
  'apply_noise',
  'apply_noise_frames',
  'build',
  'camera',
  'cantilever',
  'dataset',
  'depth_image',
  'devices',
  'interrupt',
  'fabric',
  'face_wind_forces',
  'from_unit',
  'load_ratio',
  'garment',
  'hem_mass',
  'load_depth_video',
  'load_material',
  'look_at',
  'make_depth_renderer',
  'mismatch',
  'motion',
  'one_off',
  'overhang_depth',
  'params',
  'pose_from_dict',
  'pose_to_dict',
  'config_for_mesh',
  'EDGE_SOLREF_SPACING',
  'scaled_edge_solref',
  'reference_rigidity',
  'stable_timestep',
  'resolve_backend',
  'BACKENDS',
  'rollout_fn',
  'render',
  'render_depth',
  'render_rgb',
  'render_rgb8',
  'sample_gusts',
  'sample_poses',
  'search_space',
  'sensor',
  'shade_rgb',
  'shape',
  'simulate',
  'square',
  'tabletop',
  'to_unit',
  'video',
  'world_inputs',
  'world_to_camera',
]

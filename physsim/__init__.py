"""physsim: MuJoCo flex cloth in ArcSim-style wind, batched under MJX.

Public API::

  mesh = physsim.square(25)                       # or physsim.garment('tshirt')
  model = physsim.build(mesh, 'gray_interlock')   # compiled cloth
  p = physsim.params.make(bending_scale=[1, 3], wind_speed=[3, 4], area_weight=[.18, .2])
  out = physsim.simulate(model, p, wind=physsim.Wind(gust_intensity=0.2), key=key)
  out.positions  # (B, T, V, 3); out.valid: (B,)

  ds = physsim.dataset.open_dataset('data/sim')   # 16-bit mm PNG sequences
  v = physsim.load_depth_video('capture/', source_fps=24)  # real depth video
"""

from physsim import dataset, params, video
from physsim.cloth import ClothModel, SimConfig, build, reference_rigidity
from physsim.forces import Gusts, face_wind_forces, sample_gusts
from physsim.materials import FABRICS, Fabric, Material, fabric, load_material
from physsim.mesh import GARMENTS, Mesh, garment, square
from physsim.params import Params, SearchSpace, from_unit, search_space, to_unit
from physsim.rollout import Rollout, Wind, simulate
from physsim.video import DepthVideo, load_depth_video

__all__ = [
  'FABRICS',
  'GARMENTS',
  'ClothModel',
  'DepthVideo',
  'Fabric',
  'Gusts',
  'Material',
  'Mesh',
  'Params',
  'Rollout',
  'SearchSpace',
  'SimConfig',
  'Wind',
  'build',
  'dataset',
  'fabric',
  'face_wind_forces',
  'from_unit',
  'garment',
  'load_depth_video',
  'load_material',
  'params',
  'reference_rigidity',
  'sample_gusts',
  'search_space',
  'simulate',
  'square',
  'to_unit',
  'video',
]

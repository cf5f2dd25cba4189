"""physsim: MuJoCo flex cloth in ArcSim-style wind, batched under MJX."""

from physsim.materials import FABRICS, Fabric, Material, fabric, load_material

__all__ = ['FABRICS', 'Fabric', 'Material', 'fabric', 'load_material']

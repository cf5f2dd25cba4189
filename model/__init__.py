"""PhySNet embedding, SDN baseline, triplet training and physics similarity distances.

``make_physnet`` / ``make_sdn`` build pure ``Network(init, apply)`` pairs;
``fit`` trains one with triplets (or pairs) and resumable orbax checkpoints;
``psd`` measures how far apart two videos' frame embeddings lie.
"""

from model import (
  checkpoint,
  config_io,
  contrastive,
  inputs,
  metrics,
  physnet,
  psd,
  sdn,
  splits,
  train,
  triplets,
)
from model.contrastive import Pairs, contrastive_loss, random_pairs
from model.inputs import depth_input, rgb_input
from model.metrics import embed, knn_accuracy, triplet_accuracy
from model.physnet import (
  InputStats,
  Network,
  PhySNet,
  PhySNetConfig,
  compute_stats,
  feature_map_size,
  make_physnet,
  param_count,
  with_stats,
)
from model.psd import centroid_distance, energy_distance, paired_distance
from model.sdn import SDNConfig, make_sdn, spectral_features
from model.splits import split_by_group, split_random
from model.train import (
  FitResult,
  TrainConfig,
  TrainState,
  evaluate,
  fit,
  init_state,
  load_network,
  make_network,
  make_optimizer,
  make_sampler,
  make_train_step,
  select_lr,
  split_indices,
)
from model.triplets import (
  Triplets,
  batch_hard_indices,
  batch_hard_loss,
  pk_batch,
  random_triplets,
  sample_triplets,
  triplet_loss,
)

__all__ = [
  'FitResult',
  'InputStats',
  'Network',
  'Pairs',
  'PhySNet',
  'PhySNetConfig',
  'SDNConfig',
  'TrainConfig',
  'TrainState',
  'Triplets',
  'batch_hard_indices',
  'batch_hard_loss',
  'centroid_distance',
  'checkpoint',
  'compute_stats',
  'config_io',
  'contrastive',
  'contrastive_loss',
  'depth_input',
  'embed',
  'energy_distance',
  'evaluate',
  'feature_map_size',
  'fit',
  'init_state',
  'inputs',
  'knn_accuracy',
  'load_network',
  'make_network',
  'make_optimizer',
  'make_physnet',
  'make_sampler',
  'make_sdn',
  'make_train_step',
  'metrics',
  'paired_distance',
  'param_count',
  'pk_batch',
  'physnet',
  'psd',
  'random_pairs',
  'random_triplets',
  'rgb_input',
  'sample_triplets',
  'sdn',
  'select_lr',
  'spectral_features',
  'split_by_group',
  'split_indices',
  'split_random',
  'splits',
  'train',
  'triplet_accuracy',
  'triplet_loss',
  'triplets',
  'with_stats',
]

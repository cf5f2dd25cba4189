"""The estimate pipeline as a library: the layer between physsim, model and bo and the scripts.

  recording   Recording, load_recording (frames, camera, ground truth)
  embedding   a trained network as the estimate uses it; network inputs
  simulation  the settings' Simulation section and the cloth it makes (mesh, step, pins)
  objective   EstimateConfig (in sections), Problem, the fused jitted simulate-render-score
  intake      a user's depth video and camera file into a recording; setup: what an
              estimate is built from, resolved once; takes: a protocol's recordings
  search      estimate / estimate_many / estimate_joint over bo's searches
  posterior   priors (measured wind or area weight), summaries, joints, figure
  report      errors, tables, trace and montage figures
  datasets    the simulated dataset sweep; eval_set: the real-like recordings
  training    PhySNet / SDN training per material
  demo        the end-to-end demo's settings and run
  cli         flags from config dataclasses; files, progress: atomic writes, bars

Walk one parameter (area weight) through it: ``--area_weight_sd`` ->
``EstimateConfig.measured`` -> ``posterior.log_prior`` on the grid ->
``bo.PosteriorSearch`` (its candidates scored by ``objective.Objective``, one
jit, JAX arrays throughout) -> ``posterior.summarise`` -> ``report``.
"""

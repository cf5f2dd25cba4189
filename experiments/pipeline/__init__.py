"""The estimate pipeline as a library: the layer between physsim, model and bo and the scripts.

The estimate runs as stages, each a module that imports only the stages above
it (``tests/architecture_test.py`` holds the order, ``STAGES``):

  foundations  files, layout (the run's file names), cli, progress, deadline,
               distributed, jax_cache; embedding (a trained network as the
               estimate uses it), simulation (the cloth the settings make),
               recording (frames, camera, ground truth)
  1 intake     intake: a user's depth video and camera file into a recording;
               takes: a protocol's recordings; rig: a windy test rig's
  2 measured   measurements: the readings (anemometer, scale, bending length)
               and the prior they make on the search's grid
  3 objective  EstimateConfig (a section per stage), Problem, the fused jitted
               simulate-render-score
  4 setup      calibration_tables: the shipped coverage tables; setup: what an
               estimate is built from (network, box, calibration), resolved once
  5 search     bo's searches in lockstep over the objective (search.run)
  6 posterior  summaries, intervals at calibrated levels, joints, figure
  7 reading    report: errors, tables, figures; results: estimate.json and
               posterior.npz of a finished search; joint: several recordings
               of one fabric
  8 estimate   estimation: estimate / estimate_many / estimate_joint, the
               library's entry point; user_recordings: a user's recordings
               through intake and estimate
  apps         datasets, eval_set, training, demo, fabric_files

Walk one parameter (area weight) through it: ``--area_weight_sd`` ->
``EstimateConfig.measured`` -> ``measurements.log_prior`` on the grid ->
``bo.PosteriorSearch`` (its candidates scored by ``objective.Objective``, one
jit, JAX arrays throughout) -> ``posterior.summarise`` -> ``results`` ->
``report``.
"""

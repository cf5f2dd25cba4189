"""The estimate pipeline as a library: the layer between physsim, model and bo and the scripts.

The estimate runs as stages, each a module that imports only the stages above
it (``tests/architecture_test.py`` holds the order, ``STAGES``):

  foundations  files, layout (the run's file names), cli, progress, deadline,
               distributed, jax_cache; embedding (a network as the estimate uses
               it), simulation (the cloth the settings make), recording
  1 intake     intake (a user's depth video and camera file into a recording) in
               steps: intake_record, intake_frames, intake_alignment (the
               camera placed), intake_files, cloth_view (the cloth as the camera
               sees it); takes: a protocol's recordings; rig: a windy test rig's
  2 measured   measurements: the readings (anemometer, scale, bending length)
               and the prior they make on the search's grid
  3 objective  config (EstimateConfig, a section per stage), problem, objective:
               the fused jitted simulate-render-score
  4 setup      carried_errors: a reading's and the camera's error against
               the tables'; calibration_tables: the shipped coverage tables;
               protocol_checks: the protocol joint's measured coverage; setup:
               what an estimate is built from (network, box, calibration),
               resolved once
  5 search     evaluation (one fused objective call per structure), searcher
               (Job, the bo search), resume (run.json), search (the lockstep run)
  6 posterior  posterior: summaries at calibrated levels, joints;
               posterior_figure (posterior.png); fit_check (predictive check)
  7 reading    summaries, units (what a person reads in), table_notes, report,
               advice, search_figures (trace, montage); results: estimate.json
               and posterior.npz of a finished search; joint: several
               recordings of one fabric
  8 estimate   estimation: estimate / estimate_many / estimate_joint, the
               library's entry point; user_recordings: a user's recordings
               through intake and estimate
  apps         datasets (dataset_config, dataset_folder, dataset_render),
               eval_set, training, demo, fabric_files, validation

Walk one parameter (area weight) through it: ``--area_weight_sd`` ->
``EstimateConfig.measured`` -> ``measurements.log_prior`` on the grid ->
``bo.PosteriorSearch`` (its candidates scored by ``objective.Objective``, one
jit, JAX arrays throughout) -> ``posterior.summarise`` -> ``results`` ->
``report``.
"""

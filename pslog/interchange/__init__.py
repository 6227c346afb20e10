"""Interchange with the tools of the field (see docs/interchange.md).

- :mod:`pslog.interchange.rig_formats`: calibrations of aniposelib / anipose, Pose2Sim and
  OpenCV FileStorage (YAML, XML) read as rigs, and rigs written in those formats.
- :mod:`pslog.interchange.track_formats`: fused tracks (and the ground truth) written as TUM
  trajectories (evo), JSON lines, Parquet and C3D.
- :mod:`pslog.interchange.truth_files`: a ground truth of one's own (motion capture), CSV
  ``t,x,y,z`` or TUM, read for ``pslog eval --truth``.
"""

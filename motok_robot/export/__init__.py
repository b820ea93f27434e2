"""Export to the formats neighbouring tools read (``motok-robot export``, docs/export.md):
:mod:`~motok_robot.export.bvh` (motion.npz -> BVH), :mod:`~motok_robot.export.robot_csv`
(robot.npz / servo goals -> CSV), :mod:`~motok_robot.export.lerobot` (passing run folders ->
a LeRobot-style dataset).  Light: numpy only (pyarrow, when installed, for Parquet)."""

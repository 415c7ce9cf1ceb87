"""A closed-loop office world for goal-directed navigation.

An office floor of corridors, junctions and rooms (:mod:`~torchratslam.sim.office.plan`,
built by :mod:`~torchratslam.sim.office.builder`), local movement behaviours on its
passages (:mod:`~torchratslam.sim.office.motion`), exploration
(:mod:`~torchratslam.sim.office.explore`), a forward camera, range sensor and odometry
(:mod:`~torchratslam.sim.office.sensors`), the 7 Hz closed loop with obstacles and
ground truth (:mod:`~torchratslam.sim.office.sim`) and an optional Gymnasium
environment (:mod:`~torchratslam.sim.office.env`).
"""

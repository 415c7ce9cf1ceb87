"""Closed-loop goal navigation with RatSLAM on the office floor (the experience-map paper).

The robot explores the office (:mod:`torchratslam.sim.office`) while every frame goes
through :class:`~torchratslam.pipeline.ratslam.RatSLAM`, then navigates to goals on the
experience map:

* :mod:`~torchratslam.navigation.params`: the navigator's settings and the office's
  RatSLAM configuration;
* :mod:`~torchratslam.navigation.labels`: the movement behaviour each frame executes
  (the label of Eq. 9's transitions);
* :mod:`~torchratslam.navigation.robot`: the simulated robot mapping with RatSLAM, with
  the link deletions and relearnings the frames caused;
* :mod:`~torchratslam.navigation.planner`: temporal map, route, route-loss recovery and
  behaviour arbitration in the experience map's frame;
* :mod:`~torchratslam.navigation.agent`: exploration and navigation trials;
* :mod:`~torchratslam.navigation.plots`: the paper's figures.
"""

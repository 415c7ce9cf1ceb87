"""The RatSLAM pipeline: local view, pose cells, odometry source and experience map.

Modules are chosen by name from the registries of :mod:`torchratslam.registry`
(xRatSLAM's swappable modules, without an if-chain factory), or passed as instances:

==================  ==================================================================
registry            factory signature (what a user-registered module must accept)
==================  ==================================================================
``LOCAL_VIEWS``     ``factory(params: LocalViewParams, *, dtype, device)``
``POSE_CELLS``      ``factory(params: PoseCellParams, *, dtype, device)``
``EXPERIENCE_MAPS`` ``factory(params: ExperienceMapParams)``
``ODOMETRY``        ``factory(params: VisualOdometryParams)``; the source is called
                    with each :class:`~torchratslam.messages.Frame` and returns
                    ``(vtrans, vrot, dt)``
==================  ==================================================================

Default names (registered in :mod:`torchratslam.pipeline.defaults`): local view
``"ratslam"``, pose cells ``"ratslam"``, experience map ``"ratslam"``
(:class:`ratslam_graph.experience_map.ExperienceMap`) and odometry ``"given"`` (the
reader's wheel odometry) or ``"visual"`` (intensity-profile visual odometry).

Per frame, in the reference's order: odometry source on the frame; local view on the
image; pose cells on the template (``on_view_template``); pose cells on the odometry
(``on_odometry``, returning the :class:`~ratslam_graph.messages.Action`); experience map on the
odometry, then ``apply(action, ...)`` and ``iterate()`` (relaxation).

The pipelined mode (``pipelined=True``) runs the reader + odometry + local view, the
pose cells and the experience map in three worker threads joined by bounded queues
(size 10, as in xRatSLAM). Each module still sees exactly the same messages in the same
order, so the map is identical to the sequential mode's
(:mod:`torchratslam.pipeline.threads`).

Rooms: :mod:`~torchratslam.pipeline.ratslam` (the :class:`RatSLAM` class),
:mod:`~torchratslam.pipeline.history` (the per-frame record: trajectory, ATE),
:mod:`~torchratslam.pipeline.runner` (the frames of a run, its progress bar),
:mod:`~torchratslam.pipeline.results` (:class:`StepResult`, :class:`RunResult`),
:mod:`~torchratslam.pipeline.threads` (the pipelined mode) and
:mod:`~torchratslam.pipeline.defaults` (the default stages).

Example:
    >>> from torchratslam import load_config  # doctest: +SKIP
    >>> from torchratslam.pipeline import RatSLAM  # doctest: +SKIP
    >>> from torchratslam.readers.datasets import open_data  # doctest: +SKIP
    >>> slam = RatSLAM(load_config("virtual_tour"))  # doctest: +SKIP
    >>> result = slam.run(open_data("sim:virtual_tour"), max_frames=500)  # doctest: +SKIP
"""

from torchratslam.pipeline.ratslam import RatSLAM
from torchratslam.pipeline.results import RunResult, StepResult
from torchratslam.pipeline.threads import QUEUE_SIZE

__all__ = ["QUEUE_SIZE", "RatSLAM", "RunResult", "StepResult"]

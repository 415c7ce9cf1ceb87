"""The movement behaviour each frame executes: the label of Eq. 9's transitions.

Links learnt along a corridor carry ``FOLLOW``; near a junction the behaviour held for
it (``FOLLOW``, ``LEFT`` or ``RIGHT``) labels the frames from ``junction_m`` before the
node until ``junction_m`` past it; a deliberate turn-around labels the frames until the
robot has driven ``junction_m`` again. A turn-around forced by obstacle avoidance keeps
the label the robot was moving with: from the experience it was in, the behaviour it
executed did not bring it where the link said (a transition failure, Section III D).

Example:
    >>> from torchratslam.navigation.labels import LabelState, next_label
    >>> s = next_label(LabelState(), to_node_m=5.0, held=1, event=-1, blocked=False, moved_m=0.1)
    >>> s.label
    0
"""

from __future__ import annotations

from dataclasses import dataclass

from torchratslam.sim.office.motion import Behaviour

__all__ = ["LabelState", "next_label"]


@dataclass(frozen=True)
class LabelState:
    """The labeller's state.

    Attributes:
        label: the behaviour labelling the current frame.
        sticky: a behaviour executed at a node or a deliberate turn-around, labelling
            frames until ``left_m`` reaches the junction distance (-1: none).
        left_m: metres driven since ``sticky`` was executed.
    """

    label: int = int(Behaviour.FOLLOW)
    sticky: int = -1
    left_m: float = 0.0


def next_label(
    state: LabelState,
    *,
    to_node_m: float,
    held: int,
    event: int,
    blocked: bool,
    moved_m: float,
    junction_m: float = 1.5,
) -> LabelState:
    """The label of this frame.

    Args:
        state: the previous frame's state.
        to_node_m: distance to the node ahead after the frame (m).
        held: the behaviour held for that node.
        event: the behaviour the simulator executed this frame (-1: none).
        blocked: obstacle avoidance turned the robot around this frame.
        moved_m: distance driven this frame.
        junction_m: how far from a junction its behaviour labels frames.
    """
    if blocked:
        return LabelState(state.label, state.label, 0.0)
    if event >= 0:
        return LabelState(event, event, 0.0)
    if state.sticky >= 0:
        left = state.left_m + moved_m
        if left < junction_m:
            return LabelState(state.sticky, state.sticky, left)
    if to_node_m <= junction_m and held != int(Behaviour.TURN_AROUND):
        return LabelState(int(held))
    return LabelState(int(Behaviour.FOLLOW))

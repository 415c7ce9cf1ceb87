"""Small typed messages exchanged between modules.

Data flows one way: reader -> local view -> pose cells -> experience map -> backend.
The pose cells decide what the experience map does with an :class:`Action`, exactly
as OpenRatSLAM's ``PosecellExperienceAction`` does; the experience map never reads
pose-cell state directly.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class ActionKind(enum.IntEnum):
    """What the experience map must do after a pose-cell step."""

    NONE = 0
    CREATE = 1  # create experience ``dest_id`` linked from the current one, make it current
    LINK = 2  # link the current experience to existing ``dest_id`` (loop closure), set it
    SET = 3  # make existing ``dest_id`` current without a new link


@dataclass(frozen=True)
class Action:
    """One pose-cell decision.

    Attributes:
        kind: the action.
        dest_id: the experience created, linked to or set (-1 for NONE).
        src_id: the experience that was current when the action was taken (-1 if none).
        relative_rad: relative view angle of the visual match (radians), used by the
            experience map to correct the accumulated heading, as in OpenRatSLAM.
    """

    kind: ActionKind = ActionKind.NONE
    dest_id: int = -1
    src_id: int = -1
    relative_rad: float = 0.0

    @classmethod
    def none(cls) -> Action:
        return cls()

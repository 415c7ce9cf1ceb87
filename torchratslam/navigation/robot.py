"""The office robot mapping with RatSLAM: every simulated frame goes through the pipeline
with the behaviour it executed, and the link deletions and relearnings it caused are
counted.

Example:
    >>> from torchratslam.navigation.params import office_config
    >>> from torchratslam.navigation.robot import MappingRobot
    >>> robot = MappingRobot(office_config(16), seed=0)  # doctest: +SKIP
    >>> robot.tick(0).exp_id  # doctest: +SKIP
    0
"""

from __future__ import annotations

from dataclasses import dataclass, field

import networkx as nx
import numpy as np

from torchratslam.config import RatSLAMConfig
from torchratslam.errors import InputError
from torchratslam.messages import Frame
from torchratslam.navigation.labels import LabelState, next_label
from torchratslam.pipeline.ratslam import RatSLAM
from torchratslam.sim.office.builder import Office
from torchratslam.sim.office.motion import Behaviour, options
from torchratslam.sim.office.sim import OfficeParams, OfficeSim, OfficeStep

__all__ = ["LinkEvents", "MappingRobot", "Tick", "count_link_events", "pair_keys"]


def pair_keys(src: np.ndarray, dst: np.ndarray, *, directed: bool = False) -> np.ndarray:
    """An undirected key per link (``min * 2**32 + max``; ``directed``: ``src * 2**32 +
    dst``, for maps that learn each way as its own link, ``exp_link_directed``).

    Shape:
        src, dst: (E,). Returns (E,) int64.
    """
    if directed:
        return src.astype(np.int64) * (1 << 32) + dst.astype(np.int64)
    a, b = np.minimum(src, dst).astype(np.int64), np.maximum(src, dst).astype(np.int64)
    return a * (1 << 32) + b


@dataclass
class LinkEvents:
    """Links deleted and relearnt so far (:func:`pair_keys` as keys).

    Attributes:
        deleted: how many link deletions happened.
        relearnt: how many deleted pairs were linked again.
        gone: pairs deleted and not (yet) relearnt.
        deleted_keys: every pair ever deleted, in order.
    """

    deleted: int = 0
    relearnt: int = 0
    gone: set[int] = field(default_factory=set)
    deleted_keys: list[int] = field(default_factory=list)


def count_link_events(events: LinkEvents, before: np.ndarray, after: np.ndarray) -> None:
    """Count the links deleted and relearnt between two frames into ``events``.

    Args:
        events: the counts, updated in place.
        before, after: the links' :func:`pair_keys` before and after the frame.
    """
    if len(after) == len(before) + 1 and np.array_equal(after[:-1], before):
        new, lost = after[-1:], after[:0]  # the common case: one link appended
    elif np.array_equal(after, before):
        return
    else:
        new = np.setdiff1d(after, before)
        lost = np.setdiff1d(before, after)
    for k in lost.tolist():
        events.deleted += 1
        events.gone.add(k)
        events.deleted_keys.append(k)
    for k in new.tolist():
        if k in events.gone:
            events.relearnt += 1
            events.gone.discard(k)


@dataclass(frozen=True)
class Tick:
    """One frame of the closed loop.

    Attributes:
        step: the simulator's observation and ground truth.
        exp_id: the current experience after the frame.
        label: the behaviour that labelled the frame's transition (Eq. 9).
    """

    step: OfficeStep
    exp_id: int
    label: int


class MappingRobot:
    """The simulated robot and its RatSLAM.

    Args:
        config: the RatSLAM configuration (:func:`~torchratslam.navigation.params.office_config`).
        office: the floor (default: the office floor).
        seed: sensor noise and exploration tie breaks.
        junction_m: see :func:`~torchratslam.navigation.labels.next_label`.
    """

    def __init__(
        self,
        config: RatSLAMConfig,
        *,
        office: Office | None = None,
        params: OfficeParams | None = None,
        seed: int = 0,
        junction_m: float = 1.5,
    ) -> None:
        self.sim = OfficeSim(office, params, seed=seed)
        self.slam = RatSLAM(config)
        self.junction_m = float(junction_m)
        self.links = LinkEvents()
        self._label = LabelState()
        self._keys = np.zeros(0, dtype=np.int64)
        self.exp_id = -1
        self.poses: list[np.ndarray] = []
        self.exp_ids: list[int] = []
        self._feed(self.sim.reset(seed), int(Behaviour.FOLLOW))

    @property
    def office(self) -> Office:
        """The floor."""
        return self.sim.office

    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return float(self.sim.time)

    def _feed(self, s: OfficeStep, label: int) -> None:
        vtrans, vrot, dt = (float(v) for v in s.odometry)
        frame = Frame(
            index=self.slam.frame_index,
            t=float(s.time),
            image=s.image,
            vtrans=vtrans,
            vrot=vrot,
            dt=dt,
            pose=(float(s.pose[0]), float(s.pose[1]), float(s.pose[2])),
        )
        self.exp_id = int(self.slam.step_frame(frame, behaviour=label).experience_id)
        self.poses.append(s.pose)
        self.exp_ids.append(self.exp_id)
        self._count_links()

    def _count_links(self) -> None:
        store = self.slam.experience_map.store  # type: ignore[attr-defined]
        e = store.e
        directed = self.slam.experience_map.params.exp_link_directed  # type: ignore[attr-defined]
        keys = pair_keys(store.src[:e], store.dst[:e], directed=directed)
        count_link_events(self.links, self._keys, keys)
        self._keys = keys

    def tick(self, behaviour: int) -> Tick:
        """Drive one frame holding ``behaviour`` and map it."""
        before = self.sim.pose
        s = self.sim.step(int(behaviour))
        m = self.sim.state
        o = self.office
        to_node = float(np.hypot(*(o.nodes[m.v] - s.pose[:2])))
        moved = float(np.hypot(*(s.pose[:2] - before[:2])))
        self._label = next_label(
            self._label,
            to_node_m=to_node,
            held=int(m.behaviour),
            event=s.behaviour,
            blocked=s.blocked,
            moved_m=moved,
            junction_m=self.junction_m,
        )
        self._feed(s, self._label.label)
        return Tick(s, self.exp_id, self._label.label)

    def explore(self, seconds: float) -> None:
        """Explore (least-driven passages first) for ``seconds`` of simulated time."""
        end = self.time + seconds
        while self.time < end - 1e-9:
            self.tick(self.sim.explore())

    def _open_ways(self) -> nx.Graph:
        """The passages without an obstacle on them, weighted by length."""
        o, g = self.office, nx.Graph()
        for a, b in o.edges.tolist():
            pa, pb = o.nodes[a], o.nodes[b]
            pts = pa + np.linspace(0.0, 1.0, 41)[:, None] * (pb - pa)
            if not self.sim.path_blocked(pts):
                g.add_edge(a, b, weight=float(np.hypot(*(pb - pa))))
        return g

    def drive_to(self, name: str, max_s: float = 600.0) -> None:
        """Drive to node ``name`` the shortest way round the obstacles, as an operator
        would steer it (ground truth, not the map), mapping every frame.

        Raises:
            InputError: ``name`` cannot be reached within ``max_s`` seconds.
        """
        o = self.office
        goal = o.node(name)
        g = self._open_ways()
        dist = nx.single_source_dijkstra_path_length(g, goal, weight="weight")
        end = self.time + max_s
        while float(np.hypot(*(self.sim.pose[:2] - o.nodes[goal]))) > 1e-6:
            if self.time >= end:
                raise InputError(f"the robot did not reach {name} in {max_s} s")
            m, here = self.sim.state, self.sim.pose[:2]
            ahead = float(np.hypot(*(o.nodes[m.v] - here))) + dist.get(m.v, np.inf)
            back = float(np.hypot(*(o.nodes[m.u] - here))) + dist.get(m.u, np.inf)
            line = np.linspace(0.0, 1.0, 21)[:, None]
            if self.sim.path_blocked(here + line * (o.nodes[m.v] - here)):
                ahead = np.inf  # the obstacle is ahead on this passage
            if self.sim.path_blocked(here + line * (o.nodes[m.u] - here)):
                back = np.inf  # or behind
            if back < ahead - 1e-9:
                self.tick(int(Behaviour.TURN_AROUND))
                continue
            if m.v == goal:
                self.tick(int(Behaviour.FOLLOW))
                continue
            ways = {b: w for b, w in options(o, m.u, m.v).items() if b is not Behaviour.TURN_AROUND}
            cost: dict[Behaviour, float] = {
                b: float(np.hypot(*(o.nodes[w] - o.nodes[m.v]))) + dist.get(w, np.inf)
                for b, w in ways.items()
            }
            best = min(cost, key=lambda b: cost[b]) if cost else Behaviour.TURN_AROUND
            self.tick(int(best))

    def trajectory(self) -> np.ndarray:
        """Ground-truth poses of every frame, (F, 3)."""
        return np.asarray(self.poses, dtype=np.float64).reshape(-1, 3)

    def experience_truth(self) -> np.ndarray:
        """Ground-truth ``(x, y)`` where each experience was learnt, (N, 2)."""
        store = self.slam.experience_map.store  # type: ignore[attr-defined]
        frames = np.asarray(store.frame[: store.n], dtype=np.int64)
        traj = self.trajectory()
        return traj[np.clip(frames, 0, len(traj) - 1), :2]

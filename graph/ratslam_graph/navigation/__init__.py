"""Goal-directed navigation on the experience map (the experience-map paper, Section IV).

Every function works on the map's public arrays (experience poses, link endpoints and
transition times, link counts), never on a map object's private state:

* :mod:`ratslam_graph.navigation.temporal`: the temporal map from the peak experience
  (Eqs. 10-11) by a heap-driven Dijkstra over a CSR adjacency;
* :mod:`ratslam_graph.navigation.route`: the route by gradient climbing from the goal,
  and a networkx shortest-path check;
* :mod:`ratslam_graph.navigation.arbitration`: behaviour arbitration (Fig. 7);
* :mod:`ratslam_graph.navigation.recovery`: route-loss recovery (Section IV D);
* :mod:`ratslam_graph.navigation.monitoring`: transition monitoring, Eq. 9 link
  confidence, link deletion and relearning (Section III D).

Nothing here imports torch or torchratslam.
"""

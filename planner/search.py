"""Search of the contact-state graph (networkx).

Two entry points:

* :func:`shortest_path_to_goal`: a graph that is already built (``nx.DiGraph`` whose edges carry
  a non-negative ``"cost"``) and a set of goal nodes: Dijkstra (``nx.multi_source_dijkstra`` from
  the goals on the reversed graph) or A* with a heuristic.
* :func:`best_first_search`: the graph is built while it is searched (uniform-cost expansion:
  edges are expensive to check, each needs the closure analysis and motion planning), from a
  ``successors`` function; when a goal node is reached, the path is read off the graph with
  ``nx.dijkstra_path``. A search that finds nothing returns a :class:`SearchResult` with
  ``found = False`` and the counts of every reason an edge or node was rejected, so the caller can
  say which constraint blocked it.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from collections import Counter
from collections.abc import Callable, Hashable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import networkx as nx


@dataclass(frozen=True)
class Successor:
    """An edge found by expanding a node: the target node, its cost (> 0) and the edge data."""

    node: Hashable
    cost: float
    data: Any
    #: Lazy edge: ``cost`` is a lower bound and ``validate()`` returns ``(true cost, data)`` or
    #: ``None`` if the edge is invalid. It is called only when the search pops the node through
    #: this edge (lazy evaluation: expensive motion planning is done for edges the search needs).
    validate: Callable[[], tuple[float, Any] | None] | None = None


@dataclass(frozen=True)
class SearchResult:
    """What a search found: the node path (``found``) or why it stopped."""

    found: bool
    path: tuple[Hashable, ...]
    cost: float
    expanded: int
    graph: nx.DiGraph = field(repr=False)
    rejections: dict[str, int]
    stopped_by: str  # "goal", "exhausted", "node limit", "time limit"
    lazy_checked: int = 0  # lazy edges validated

    def blocking_reason(self) -> str:
        """The constraint that most often rejected an edge, in words."""
        if self.found:
            return ""
        if self.stopped_by in ("node limit", "time limit"):
            base = f"search stopped: {self.stopped_by} reached after {self.expanded} expansions"
        else:
            base = f"every reachable state ({self.graph.number_of_nodes()}) was expanded without reaching the goal"
        if self.rejections:
            top = sorted(self.rejections.items(), key=lambda kv: -kv[1])
            return base + "; rejected transitions: " + ", ".join(f"{k} ({v})" for k, v in top)
        return base + "; no transition was rejected (the graph has no edge towards the goal)"


def _check_graph(G: Any, weight: str) -> None:
    if not isinstance(G, nx.DiGraph):
        raise TypeError(f"expected a networkx DiGraph, got {type(G).__name__}")
    for u, v, c in G.edges(data=weight):
        if c is None or not isinstance(c, int | float) or not math.isfinite(c) or c < 0:
            raise ValueError(f"edge {u!r} -> {v!r} needs a finite non-negative '{weight}', got {c!r}")


def shortest_path_to_goal(
    G: nx.DiGraph,
    source: Hashable,
    goals: Iterable[Hashable],
    *,
    weight: str = "cost",
    heuristic: Callable[[Hashable, Hashable], float] | None = None,
) -> SearchResult:
    """Shortest path in a built graph from ``source`` to the nearest of ``goals``.

    Dijkstra without a heuristic (one multi-source run on the reversed graph), A* with one
    (``nx.astar_path`` per goal). Raises ``ValueError``/``TypeError`` for malformed input
    (unknown source, negative or missing costs); a goal that cannot be reached is a result with
    ``found = False``, not an exception.
    """
    _check_graph(G, weight)
    if source not in G:
        raise ValueError(f"source {source!r} is not a node of the graph")
    goal_list = list(goals)
    if not goal_list:
        raise ValueError("at least one goal node is needed")
    missing = [g for g in goal_list if g not in G]
    if missing:
        raise ValueError(f"goal nodes not in the graph: {missing!r}")
    if heuristic is None:
        dist, paths = nx.multi_source_dijkstra(G.reverse(copy=False), set(goal_list), weight=weight)
        if source not in dist:
            return SearchResult(False, (), math.inf, G.number_of_nodes(), G, {}, "exhausted")
        return SearchResult(True, tuple(reversed(paths[source])), float(dist[source]),
                            G.number_of_nodes(), G, {}, "goal")
    best: tuple[float, list[Hashable]] | None = None
    for g in goal_list:
        try:
            p = nx.astar_path(G, source, g, heuristic=heuristic, weight=weight)
        except nx.NetworkXNoPath:
            continue
        c = float(nx.path_weight(G, p, weight))
        if best is None or c < best[0]:
            best = (c, p)
    if best is None:
        return SearchResult(False, (), math.inf, G.number_of_nodes(), G, {}, "exhausted")
    return SearchResult(True, tuple(best[1]), best[0], G.number_of_nodes(), G, {}, "goal")


def best_first_search(
    start: Hashable,
    successors: Callable[[Hashable], Sequence[Successor]],
    is_goal: Callable[[Hashable], bool],
    *,
    rejections: Counter[str] | None = None,
    max_expansions: int = 200,
    time_limit: float | None = None,
    progress: Callable[[int, Hashable], None] | None = None,
    heuristic: Callable[[Hashable], float] | None = None,
) -> SearchResult:
    """Uniform-cost search that builds the graph as it goes (Dijkstra's order of expansion).

    ``successors(node)`` checks and returns the outgoing edges; it may add counts to
    ``rejections`` (``reason -> count``) for the transitions it refused. The path to the first
    goal node popped from the queue is optimal for the graph expanded so far and is computed with
    ``nx.dijkstra_path`` on it. With ``heuristic`` (a lower bound of the cost to a goal, >= 0) the
    queue is ordered by ``g + h`` (A*); the path is then optimal when ``h`` never overestimates.
    Lazy successors (with ``validate``) enter the queue with their
    lower-bound cost and are validated when popped, so a node is expanded only at its validated
    cost and the first goal popped is still the cheapest (lower bounds never overestimate).
    """
    if max_expansions < 1:
        raise ValueError("max_expansions must be at least 1")
    if time_limit is not None and not time_limit > 0:
        raise ValueError("time_limit must be positive")
    rej: Counter[str] = rejections if rejections is not None else Counter()
    G = nx.DiGraph()
    G.add_node(start)
    t0 = time.perf_counter()
    tie = itertools.count()
    # entries (g, tie, node, pending lazy edge (parent, parent g, successor) or None)
    Entry = tuple[float, int, Hashable, "tuple[Hashable, float, Successor] | None"]
    def h(n: Hashable) -> float:
        v = 0.0 if heuristic is None else float(heuristic(n))
        if not (math.isfinite(v) and v >= 0.0):
            raise ValueError(f"heuristic of {n!r} is {v!r}; it must be finite and >= 0")
        return v

    queue: list[Entry] = [(h(start), next(tie), start, None)]
    done: set[Hashable] = set()
    best: dict[Hashable, float] = {start: 0.0}
    expanded = 0
    lazy_checked = 0
    stopped = "exhausted"
    while queue:
        f, _, node, pending = heapq.heappop(queue)
        hn = h(node)
        g = f - hn
        if node in done or g > best.get(node, math.inf) + 1e-9:
            continue
        if pending is not None:  # a lazy edge whose lower bound is the smallest in the queue
            parent, g_parent, succ = pending
            assert succ.validate is not None
            lazy_checked += 1
            checked = succ.validate()
            if checked is None:
                continue
            cost, data = checked
            if not (math.isfinite(cost) and cost >= succ.cost - 1e-9):
                raise ValueError(f"lazy edge {parent!r} -> {node!r}: cost {cost!r} is below its bound {succ.cost!r}")
            if not G.has_edge(parent, node) or G.edges[parent, node]["cost"] > cost:
                G.add_edge(parent, node, cost=cost, data=data)
            ng = g_parent + cost
            if ng < best.get(node, math.inf):
                best[node] = ng
                heapq.heappush(queue, (ng + hn, next(tie), node, None))
            continue
        if is_goal(node):
            path = nx.dijkstra_path(G, start, node, weight="cost")
            return SearchResult(True, tuple(path), float(nx.path_weight(G, path, "cost")), expanded, G,
                                dict(rej), "goal", lazy_checked)
        if expanded >= max_expansions:
            stopped = "node limit"
            break
        if time_limit is not None and time.perf_counter() - t0 > time_limit:
            stopped = "time limit"
            break
        done.add(node)
        expanded += 1
        if progress is not None:
            progress(expanded, node)
        for s in successors(node):
            if not (math.isfinite(s.cost) and s.cost > 0):
                raise ValueError(f"successor {s.node!r} of {node!r} has cost {s.cost!r}; costs must be > 0")
            if s.node in done:
                continue
            ng = g + s.cost
            if ng >= best.get(s.node, math.inf):
                continue
            if s.validate is not None:  # optimistic entry; validated when popped
                heapq.heappush(queue, (ng + h(s.node), next(tie), s.node, (node, g, s)))
                continue
            if not G.has_edge(node, s.node) or G.edges[node, s.node]["cost"] > s.cost:
                G.add_edge(node, s.node, cost=s.cost, data=s.data)
            best[s.node] = ng
            heapq.heappush(queue, (ng + h(s.node), next(tie), s.node, None))
    return SearchResult(False, (), math.inf, expanded, G, dict(rej), stopped, lazy_checked)

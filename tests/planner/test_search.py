"""Graph search on tiny hand-built graphs with known shortest paths, and "no path" cases."""

from __future__ import annotations

from collections import Counter

import networkx as nx
import pytest

from planner.search import Successor, best_first_search, shortest_path_to_goal


def diamond() -> nx.DiGraph:
    G = nx.DiGraph()
    G.add_edge("s", "a", cost=1.0)
    G.add_edge("s", "b", cost=4.0)
    G.add_edge("a", "b", cost=1.0)
    G.add_edge("a", "g", cost=6.0)
    G.add_edge("b", "g", cost=1.0)
    G.add_node("island")
    return G


def test_dijkstra_known_shortest_path() -> None:
    r = shortest_path_to_goal(diamond(), "s", ["g"])
    assert r.found and r.path == ("s", "a", "b", "g") and r.cost == pytest.approx(3.0)


def test_astar_agrees_with_dijkstra() -> None:
    r = shortest_path_to_goal(diamond(), "s", ["g"], heuristic=lambda u, v: 0.0)
    assert r.path == ("s", "a", "b", "g") and r.cost == pytest.approx(3.0)


def test_nearest_of_several_goals() -> None:
    r = shortest_path_to_goal(diamond(), "s", ["g", "b"])
    assert r.path == ("s", "a", "b") and r.cost == pytest.approx(2.0)


def test_no_path_is_a_result_not_an_exception() -> None:
    r = shortest_path_to_goal(diamond(), "s", ["island"])
    assert not r.found and r.path == () and "without reaching the goal" in r.blocking_reason()


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda G: G.add_edge("s", "x", cost=-1.0), "non-negative"),
        (lambda G: G.add_edge("s", "y"), "non-negative"),
        (lambda G: G.add_edge("s", "z", cost=float("nan")), "non-negative"),
    ],
)
def test_malformed_costs_raise(mutate, match) -> None:  # type: ignore[no-untyped-def]
    G = diamond()
    mutate(G)
    with pytest.raises(ValueError, match=match):
        shortest_path_to_goal(G, "s", ["g"])


def test_unknown_nodes_and_types_raise() -> None:
    with pytest.raises(ValueError, match="source"):
        shortest_path_to_goal(diamond(), "nope", ["g"])
    with pytest.raises(ValueError, match="goal"):
        shortest_path_to_goal(diamond(), "s", ["nope"])
    with pytest.raises(ValueError, match="at least one"):
        shortest_path_to_goal(diamond(), "s", [])
    with pytest.raises(TypeError):
        shortest_path_to_goal(nx.Graph(), "s", ["g"])  # type: ignore[arg-type]


def _expander(G: nx.DiGraph, lazy_fail: set[tuple[str, str]] = frozenset(), lazy: bool = False,  # type: ignore[assignment]
              calls: Counter[str] | None = None):  # type: ignore[no-untyped-def]
    def successors(u: str) -> list[Successor]:
        out = []
        for v in G.successors(u):
            c = G.edges[u, v]["cost"]
            if lazy:
                def validate(u: str = u, v: str = v, c: float = c):  # type: ignore[no-untyped-def]
                    if calls is not None:
                        calls[f"{u}{v}"] += 1
                    return None if (u, v) in lazy_fail else (c, f"{u}->{v}")

                out.append(Successor(v, c / 2, None, validate))  # lower bound: half the true cost
            else:
                out.append(Successor(v, c, f"{u}->{v}"))
        return out

    return successors


def test_best_first_search_finds_known_shortest_path() -> None:
    G = diamond()
    r = best_first_search("s", _expander(G), lambda n: n == "g")
    assert r.found and r.path == ("s", "a", "b", "g") and r.cost == pytest.approx(3.0)
    assert r.graph.edges["b", "g"]["data"] == "b->g"


def test_lazy_edges_give_the_same_optimum_and_skip_failed_ones() -> None:
    G = diamond()
    calls: Counter[str] = Counter()
    r = best_first_search("s", _expander(G, lazy=True, calls=calls), lambda n: n == "g")
    assert r.path == ("s", "a", "b", "g") and r.cost == pytest.approx(3.0)
    assert calls["ag"] == 0  # never needed: its bound (3) exceeds the optimum reached first
    # the edge a->b fails when validated: the path must avoid it
    r2 = best_first_search("s", _expander(G, lazy_fail={("a", "b")}, lazy=True), lambda n: n == "g")
    assert r2.path == ("s", "b", "g") and r2.cost == pytest.approx(5.0)
    assert not r2.graph.has_edge("a", "b")


def test_search_without_path_reports_rejections() -> None:
    G = nx.DiGraph()
    G.add_edge("s", "a", cost=1.0)
    rej: Counter[str] = Counter()

    def successors(u: str) -> list[Successor]:
        rej["no stationary grasp (18)"] += 1
        return [Successor(v, 1.0, None) for v in G.successors(u)]

    r = best_first_search("s", successors, lambda n: n == "g", rejections=rej)
    assert not r.found and r.stopped_by == "exhausted" and r.expanded == 2
    assert "no stationary grasp (18) (2)" in r.blocking_reason()


def test_node_limit_and_bad_arguments() -> None:
    def chain(u: int) -> list[Successor]:
        return [Successor(u + 1, 1.0, None)]

    r = best_first_search(0, chain, lambda n: n == 1000, max_expansions=5)
    assert not r.found and r.stopped_by == "node limit" and "node limit" in r.blocking_reason()
    with pytest.raises(ValueError):
        best_first_search(0, chain, lambda n: False, max_expansions=0)
    with pytest.raises(ValueError):
        best_first_search(0, lambda u: [Successor(1, 0.0, None)], lambda n: False)

"""The compiled-problem cache's key (isac_mission/nlp_cache.py): the same problem always finds
its file, and any change of expressions, options or name is another file."""

from __future__ import annotations

import casadi as ca

from isac_mission.nlp_cache import nlp_function, problem_key


def toy(weight: float) -> dict[str, ca.SX]:
    x, p = ca.SX.sym("x", 2), ca.SX.sym("p")
    return {"x": x, "p": p, "f": weight * ca.sumsqr(x - p), "g": x[0] * x[1]}


OPTIONS = {"print_time": False, "ipopt": {"max_iter": 60, "tol": 1e-7}}


def test_the_same_problem_built_twice_has_the_same_key() -> None:
    first = problem_key("horizon", nlp_function("horizon", toy(2.0)), OPTIONS)
    again = problem_key("horizon", nlp_function("horizon", toy(2.0)), dict(OPTIONS))
    assert first == again and len(first) == 64


def test_expressions_options_and_name_each_change_the_key() -> None:
    base = problem_key("horizon", nlp_function("horizon", toy(2.0)), OPTIONS)
    other_constant = problem_key("horizon", nlp_function("horizon", toy(3.0)), OPTIONS)
    other_cap = problem_key(
        "horizon", nlp_function("horizon", toy(2.0)), {**OPTIONS, "ipopt": {"max_iter": 61}}
    )
    other_name = problem_key("polish", nlp_function("polish", toy(2.0)), OPTIONS)
    assert len({base, other_constant, other_cap, other_name}) == 4


def test_a_function_among_the_options_enters_the_key_by_what_it_computes() -> None:
    """nlpsol's given derivatives (the horizon's hess_lag) are Functions: their text form names
    them only, so the key hashes their serialized selves."""
    x = ca.SX.sym("x", 2)

    def with_hessian(weight: float) -> dict[str, object]:
        return {**OPTIONS, "hess_lag": ca.Function("nlp_hess_l", [x], [weight * x])}

    function = nlp_function("horizon", toy(2.0))
    first = problem_key("horizon", function, with_hessian(2.0))
    assert first == problem_key("horizon", function, with_hessian(2.0))
    assert first != problem_key("horizon", function, with_hessian(3.0))
    assert first != problem_key("horizon", function, OPTIONS)


def test_the_cache_s_events_read_as_one_line_of_counts_and_the_unusual_ones_whole() -> None:
    """What `run` prints of its planner problems: counts by kind, then any event that is
    news (a file that did not load) as it was said; the wording is the cache's own."""
    from isac_mission.nlp_cache import events_summary

    events = [
        "polish-1: compiled, loaded from the cache",
        "horizon-2: compiled, loaded from the cache",
        "horizon_warm: shares the compiled derivatives of horizon-2.casadi",
        "polish: interpreted until polish-3.casadi is compiled (in the background)",
        "polish: compiled in 4.2 s",
        "horizon-4.casadi: could not be loaded (bad ELF); removed",
    ]
    assert events_summary(events) == [
        "2 loaded compiled from the cache, 1 sharing another's compiled derivatives, "
        "1 interpreted while they compile in the background, 1 compiled while the mission flew",
        "horizon-4.casadi: could not be loaded (bad ELF); removed",
    ]
    assert events_summary([]) == []

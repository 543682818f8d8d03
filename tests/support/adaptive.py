"""Adaptive renders of synthetic tracers without threads (tests of the allocation rule)."""


def run_units_in_order(units, trace_unit, add_result, stop_requested, abort):
    """``render_adaptive``'s ``run_units`` on the calling thread: every unit traced and added in
    order, never stopped."""
    for u in units:
        add_result(trace_unit(u))
    return False


def empty_stats():
    """The render statistics ``render_adaptive`` adds to."""
    return {"rays": 0, "shadow_rays": 0, "nonfinite": 0}

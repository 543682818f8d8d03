"""Adaptive renders of synthetic tracers without threads (tests of the allocation rule)."""

from engine.render.adaptive import AdaptiveRounds
from engine.render.driver import drive
from engine.render.plan import RenderPlan, RenderRequest
from engine.scene.description import RenderSettings


class InOrder:
    """An executor (engine.render.driver) that traces every unit on the calling thread, in order, and
    never stops."""

    local = True
    error = None
    workers = 1

    def stats(self):
        return {}

    def run(self, units, job, tracer, add_result, stop_requested, abort):
        for unit in units:
            add_result(job(tracer, unit, abort))
        return False


def adaptive_render(tracer, film, halves, spp, batch_rays, adaptive, window=None):
    """(stop reason, stats) of an adaptive render of ``tracer`` (anything with ``trace(pixel, sample,
    abort)``) into ``film`` and ``halves`` with the one driver, on the calling thread."""
    settings = RenderSettings(spp=spp, batch_rays=batch_rays, sampler="independent")
    plan = RenderPlan(settings, "", (), (), "", film.width, film.height, window, 1)
    stats = plan.stats()
    drive(AdaptiveRounds(plan, film, halves, adaptive, 1, stats), film, tracer, InOrder(), stats, RenderRequest())
    return stats["stop_reason"], stats

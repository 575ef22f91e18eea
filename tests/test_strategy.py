"""One vocabulary for a strategy (``tracer.strategy.Strategy``): the options the command line, the
API and check entries give (``from_options``), the record an EXR keeps (``to_record`` and
``from_record``) and the one name files, rows and curves use (``slug``) agree with each other."""

from __future__ import annotations

import itertools

import pytest

from tracer.record import ESTIMATOR_FIELDS, RenderRecord
from tracer.strategy import ALLOCATIONS, HEURISTICS, Strategy, light_samplings, light_selections


def _every_strategy() -> list[Strategy]:
    """Every strategy name with a spread of counts, heuristics, light samplings and selections
    (the invalid combinations skipped as ``Strategy`` refuses them)."""
    out = []
    for name in ("uniform", "cosine", "bsdf", "light", "mis"):
        for heuristic, counts, one, sampling, selection, allocation in itertools.product(
                HEURISTICS, ((1, 1), (2, 1), (1, 3), (0, 2), (4, 0)), (False, True), light_samplings(),
                light_selections(), ALLOCATIONS):
            try:
                out.append(Strategy(name, heuristic, *counts, one, selection, sampling, allocation))
            except ValueError:
                pass
    for candidates, sources, heuristic in itertools.product((1, 4, 16), ("light", "light+bsdf"), HEURISTICS):
        try:
            out.append(Strategy.ris(candidates, sources, heuristic=heuristic))
        except ValueError:
            pass
    return out


def _estimator(strategy: Strategy) -> tuple:
    """What a render of ``strategy`` computes: its record without the fields it does not use (a
    light selection without light samples, one-sample without both techniques)."""
    record = strategy.to_record()
    record["light_selection"] = record["light_selection"] if strategy.light_count else "none"
    record["one_sample"] = strategy.one_sample_mis
    return tuple(sorted(record.items()))


def test_a_record_gives_back_its_strategy_and_equal_slugs_are_equal_strategies():
    """For every strategy: writing its record and reading it back gives a strategy with the same
    record and slug (so a resume renders what the file holds), and no two strategies that render
    differently share a slug (their files or table rows would overwrite each other)."""
    strategies = _every_strategy()
    assert len(strategies) > 500
    by_slug: dict[str, tuple] = {}
    for strategy in strategies:
        record = strategy.to_record()
        assert set(record) == set(ESTIMATOR_FIELDS) - {"sampler"}
        again = Strategy.from_record(record)
        assert again.to_record() == record and again.slug == strategy.slug, strategy
        assert Strategy.from_record(RenderRecord(**record)).to_record() == record
        estimator = _estimator(strategy)
        assert by_slug.setdefault(strategy.slug, estimator) == estimator, (strategy.slug, estimator,
                                                                           by_slug[strategy.slug])


def test_options_left_out_are_the_defaults_and_ris_takes_its_candidates():
    """``from_options`` with nothing given is ``Strategy()``; ris's counts come from its
    candidates and sources; a bad option is a ValueError naming it."""
    assert Strategy.from_options() == Strategy()
    assert Strategy.from_options("light", light_samples=3) == Strategy("light", light_samples=3)
    assert Strategy.from_options("ris") == Strategy.ris()
    ris = Strategy.from_options("ris", ris_candidates=8, ris_sources="light+bsdf", heuristic="balance")
    assert (ris.light_samples, ris.bsdf_samples, ris.heuristic) == (4, 4, "balance")
    with pytest.raises(ValueError, match="heuristic"):
        Strategy.from_options("mis", heuristic="loudest")
    with pytest.raises(ValueError, match="names no strategy"):
        Strategy.from_record({})


def test_old_records_read_with_the_defaults():
    """A file of an older tracer leaves out the fields that came later (light sampling,
    selection, allocation): they read as the defaults those versions used."""
    old = Strategy.from_record({"strategy": "mis", "heuristic": "balance", "light_samples": 1,
                                "bsdf_samples": 1})
    assert old == Strategy("mis", "balance")
    assert [Strategy(s).slug for s in ("mis", "light", "bsdf")] == ["mis", "light", "bsdf"]
    assert Strategy("mis", "balance", 2, 1, one_sample=True).slug == "mis_l2_b1_one-sample_balance"
    assert Strategy("light", light_samples=4, light_selection="uniform").slug == "light_x4_uniform-lights"

"""The lossy, late channel model (sim/impairment.py), its event-loop adapter (sim/impaired_io.py)
and its configuration (isac_mission/config/impairment.py: the scenario section and the
`--impair-link` flag).

Statistical bounds: each rate is checked against its binomial standard deviation at 5 sigma
(a false failure about once in 3.5 million runs, for a fixed seed never), and each bound is
shown to reject a channel that does something else (the negative controls), so it can fail.
"""

from __future__ import annotations

import asyncio
import itertools
import math

import numpy as np
import pytest
from scipy import stats

from isac_mission.config import (
    ChannelImpairmentConfig,
    ImpairmentConfig,
    apply_impairment_flags,
    parse_scenario,
    read_scenario_data,
)
from isac_mission.errors import ConfigError
from sim.impaired_io import DelayLine, ImpairedPublisher, wall_per_sim
from sim.impairment import ImpairedChannel, channel_rng

N = 20_000
SIGMAS = 5.0


def _channel(seed: int = 1, **fields: float) -> ImpairedChannel:
    return ImpairedChannel(ChannelImpairmentConfig(**fields), channel_rng(seed, 0, 0, 0, 0))


def _draws(ch: ImpairedChannel, n: int = N) -> list[list[float]]:
    return [ch.deliveries() for _ in range(n)]


def _within_binomial(count: int, n: int, p: float) -> bool:
    return abs(count - n * p) <= SIGMAS * math.sqrt(n * p * (1 - p))


def test_loss_rate_is_the_configured_probability() -> None:
    draws = _draws(_channel(loss=0.2))
    lost = sum(not d for d in draws)
    assert _within_binomial(lost, N, 0.2), lost
    assert not _within_binomial(lost, N, 0.18)  # the bound tells 20 % from 18 %
    ch = _channel(loss=0.2)
    _draws(ch)
    assert ch.counts.offered == N and ch.counts.lost + ch.counts.delivered == N


def test_losses_are_independent_packet_to_packet() -> None:
    # Bernoulli losses: P(lost | previous lost) equals the loss rate (no bursts).
    lost = np.array([not d for d in _draws(_channel(loss=0.3))])
    after_loss = lost[1:][lost[:-1]]
    assert _within_binomial(int(after_loss.sum()), len(after_loss), 0.3)


def test_latency_is_uniform_between_latency_minus_and_plus_jitter() -> None:
    delays_ms = np.array([d[0] for d in _draws(_channel(latency_ms=100, jitter_ms=50))]) * 1e3
    assert delays_ms.min() >= 50.0 and delays_ms.max() <= 150.0
    assert delays_ms.min() < 51.0 and delays_ms.max() > 149.0  # the whole band is used
    sigma_mean = 100.0 / math.sqrt(12) / math.sqrt(N)
    assert abs(delays_ms.mean() - 100.0) <= SIGMAS * sigma_mean
    assert stats.kstest(delays_ms, stats.uniform(50.0, 100.0).cdf).pvalue > 1e-4
    # Negative controls: a normal of the same mean and spread, a wider band, are rejected.
    assert stats.kstest(delays_ms, stats.norm(100.0, 100.0 / math.sqrt(12)).cdf).pvalue < 1e-4
    assert stats.kstest(delays_ms, stats.uniform(40.0, 120.0).cdf).pvalue < 1e-4


def test_fixed_latency_without_jitter_and_no_impairment_passes_at_once() -> None:
    assert _draws(_channel(latency_ms=80), 100) == [[0.08]] * 100
    clean = _channel()
    assert not clean.active
    assert _draws(clean, 100) == [[0.0]] * 100


def test_duplicates_arrive_at_the_configured_rate_with_their_own_latency() -> None:
    ch = _channel(duplicate=0.1, latency_ms=100, jitter_ms=50)
    draws = _draws(ch)
    twice = [d for d in draws if len(d) == 2]
    assert all(1 <= len(d) <= 2 for d in draws)
    assert _within_binomial(len(twice), N, 0.1) and ch.counts.duplicated == len(twice)
    assert ch.counts.delivered == N + len(twice)
    first, second = np.array(twice).T
    assert abs(stats.pearsonr(first, second).statistic) < SIGMAS / math.sqrt(len(twice))
    assert stats.kstest(second * 1e3, stats.uniform(50.0, 100.0).cdf).pvalue > 1e-4


def test_held_back_packets_are_overtaken_by_the_ones_sent_after_them() -> None:
    # Packets every 10 ms through a fixed 20 ms latency: a held-back one (+95 ms) arrives after
    # the (not held-back) packets sent within the next 95 ms, the others in the order sent.
    ch = _channel(latency_ms=20, reorder=0.1, reorder_delay_ms=95)
    n, period_s = 5000, 0.01
    arrival = {k: k * period_s + d[0] for k, d in enumerate(_draws(ch, n))}
    held = {k for k, t in arrival.items() if t - k * period_s > 0.05}
    assert _within_binomial(len(held), n, 0.1) and ch.counts.held_back == len(held)
    on_time = sorted(set(arrival) - held)
    assert sorted(on_time, key=arrival.__getitem__) == on_time
    for k in held:
        overtook = {j for j in on_time if j > k and arrival[j] < arrival[k]}
        assert overtook == {j for j in range(k + 1, min(k + 10, n)) if j not in held}, k
    # Negative control: without reordering nothing is overtaken.
    plain = {k: k * period_s + d[0] for k, d in enumerate(_draws(_channel(latency_ms=20), n))}
    assert sorted(plain, key=plain.__getitem__) == list(range(n))


def test_jitter_alone_reorders_packets_closer_than_its_spread() -> None:
    ch = _channel(latency_ms=100, jitter_ms=50)
    draws = _draws(ch, 2000)
    arrivals = [k * 0.05 + d[0] for k, d in enumerate(draws)]  # 20 Hz, 100 ms spread
    inversions = sum(1 for a, b in itertools.pairwise(arrivals) if b < a)
    # Two uniforms of width w, 0.5 w apart: P(later one first) = (1 - 0.5)^2 / 2 = 1/8.
    assert _within_binomial(inversions, 1999, 0.125), inversions


def test_the_same_seed_replays_the_same_draws_and_others_differ() -> None:
    fields = {"loss": 0.2, "latency_ms": 100.0, "jitter_ms": 50.0, "duplicate": 0.05}
    assert _draws(_channel(7, **fields), 500) == _draws(_channel(7, **fields), 500)
    assert _draws(_channel(7, **fields), 500) != _draws(_channel(8, **fields), 500)
    cfg = ChannelImpairmentConfig(**fields)  # type: ignore[arg-type]
    paths = [(0, 0, 0, 0), (0, 0, 0, 1), (0, 1, 0, 0), (1, 0)]
    runs = [_draws(ImpairedChannel(cfg, channel_rng(7, *p)), 200) for p in paths]
    assert all(a != b for i, a in enumerate(runs) for b in runs[i + 1 :])
    # A channel's draws do not depend on the world's noise streams of the same seed.
    world = np.random.default_rng(np.random.SeedSequence(7).spawn(2)[0]).random(5)
    assert not np.allclose(world, channel_rng(7, 0, 0, 0, 0).random(5))


async def test_delay_line_delivers_in_arrival_order_and_close_drops_what_is_in_flight() -> None:
    got: list[int] = []
    ch = _channel(latency_ms=30, jitter_ms=25)
    line = DelayLine(ch, got.append, wall_per_sim_s=0.5)  # speed 2: 5-27.5 ms of wall time
    loop = asyncio.get_running_loop()
    due: dict[int, float] = {}  # each packet's wall deadline: its push time plus its delay
    line.observer = lambda args, d: due.__setitem__(args[0], loop.time() + 0.5 * d[0])
    for k in range(40):
        line.push(k)
    assert line.in_flight == 40 and got == []
    deadline = loop.time() + 10.0
    while len(got) < 40 and loop.time() < deadline:
        await asyncio.sleep(0.01)
    assert sorted(got) == list(range(40))
    # By each packet's own deadline (its delay counted from its own push: on a loaded machine
    # the 40 pushes spanned more than the millisecond the delays alone were compared within).
    assert all(due[a] <= due[b] + 1e-4 for a, b in itertools.pairwise(got))
    assert got != list(range(40))  # and so out of the order sent
    for k in range(10):
        line.push(100 + k)
    line.close()
    await asyncio.sleep(0.1)
    assert len(got) == 40 and line.in_flight == 0
    line.push(200)
    assert line.in_flight == 0


async def test_impaired_publisher_delays_only_its_keys() -> None:
    class Bus:
        def __init__(self) -> None:
            self.seen: list[str] = []

        def publish(self, key: str, payload: bytes) -> None:
            self.seen.append(key)

    bus = Bus()
    lossy = DelayLine(_channel(loss=1.0), bus.publish, wall_per_sim(1.0))
    pub = ImpairedPublisher(bus, {"det/0": lossy})
    for _ in range(20):
        pub.publish("det/0", b"x")
        pub.publish("truth", b"y")
    assert bus.seen == ["truth"] * 20 and lossy.channel.counts.lost == 20
    assert wall_per_sim(math.inf) == 0.0 and wall_per_sim(4.0) == 0.25


# ------------------------------------------------------------------------------ configuration


def _paper_with(impairment: object) -> object:
    data, _ = read_scenario_data("paper")
    return parse_scenario({**data, "impairment": impairment}, "test.yaml")


def test_scenario_section_both_directions_per_vehicle_and_detections() -> None:
    s = _paper_with(
        {
            "seed": 5,
            "mavlink": {"loss": 0.2, "latency_ms": 100, "jitter_ms": 50},
            "vehicles": {1: {"downlink": {"loss": 0.5}}},
            "detections": {"latency_ms": 300, "jitter_ms": 200},
        }
    )
    imp = s.impairment  # type: ignore[attr-defined]
    assert imp.seed == 5 and imp.active
    assert imp.link_for(0).uplink == imp.link_for(0).downlink
    assert imp.link_for(0).uplink.loss == 0.2 and imp.link_for(2) == imp.mavlink
    assert imp.link_for(1).downlink.loss == 0.5 and not imp.link_for(1).uplink.active
    assert imp.detections.latency_ms == 300
    assert not _paper_with({}).impairment.active  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ({"mavlink": {"loss": 1.5}}, "impairment.mavlink.uplink.loss: Input should be less"),
        ({"mavlink": {"downlink": {"latency_ms": -1}}}, "impairment.mavlink.downlink.latency_ms"),
        ({"mavlink": {"latency_ms": 10, "jitter_ms": 20}}, "jitter_ms (20) must not exceed"),
        ({"mavlink": {"lose": 0.1}}, "impairment.mavlink.lose: unknown key"),
        ({"detections": {"loss": "lots"}}, "impairment.detections.loss: Input should be a"),
        ({"vehicles": {7: {"loss": 0.1}}}, "impairment.vehicles.7: no vehicle 7 (M = 3)"),
        ({"mavlink": {"loss": 0.1, "uplink": {}}}, "give either the channel keys"),
    ],
)
def test_a_bad_section_names_the_field(section: object, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        _paper_with(section)
    assert message in str(err.value)
    assert str(err.value).startswith("test.yaml: impairment")


def test_flags_set_every_vehicle_one_vehicle_one_direction_and_detections() -> None:
    imp = apply_impairment_flags(
        ImpairmentConfig(),
        [
            "loss=0.2,latency_ms=100,jitter_ms=50",
            "1:down:loss=0.5",
            "2:up:duplicate=0.1",
            "detections:loss=0.1,latency_ms=300",
        ],
    )
    assert imp.mavlink.uplink == imp.mavlink.downlink
    assert imp.mavlink.uplink.loss == 0.2 and imp.mavlink.uplink.jitter_ms == 50
    assert imp.link_for(1).downlink.loss == 0.5 and imp.link_for(1).uplink.loss == 0.2
    assert imp.link_for(2).uplink.duplicate == 0.1 and imp.link_for(2).downlink.duplicate == 0
    assert imp.link_for(0) == imp.mavlink
    assert imp.detections.loss == 0.1 and imp.detections.latency_ms == 300


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("loss=1.2", "--impair-link: mavlink.uplink.loss: Input should be less than or equal"),
        ("loss=abc", "'loss=abc': loss: not a number (got 'abc')"),
        ("lag=3", "'lag=3': expected KEY=VALUE with KEY one of loss, latency_ms"),
        ("radio:loss=0.1", "target 'radio': expected all, a vehicle index or detections"),
        ("detections:up:loss=0.1", "detections have one direction"),
        ("latency_ms=10,jitter_ms=30", "jitter_ms (30) must not exceed latency_ms (10)"),
    ],
)
def test_a_bad_flag_names_the_spec_and_the_field(spec: str, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        apply_impairment_flags(ImpairmentConfig(), [spec])
    assert message in str(err.value)

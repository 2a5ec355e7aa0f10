"""The launcher believes a world state only if it is not older than the last it took
(issue 23, case 3): replayed old states, authentic, must neither count as the robots'
progress nor hide a stall."""

from __future__ import annotations

import pytest

from bestofn_swarm.wire import auth, keyspace, names, protocol
from deploy.cli import build_parser
from deploy.launcher.follower import Follower, Heard
from deploy.launcher.plan import plan_from_args

KEYRING = auth.Keyring(secret=bytes(range(32)))


@pytest.fixture
def follower() -> Follower:
    args = build_parser(["run"]).parse_args(["run", "--robots", "2", "--no-record"])
    return Follower(plan_from_args(args), clock=lambda: 0.0)


def state(follower: Follower, tick: int, x: float) -> Heard:
    poses = [protocol.Pose(id=robot, x=x, y=0.0, theta=0.0) for robot in range(2)]
    payload = protocol.encode(
        protocol.WorldState(
            v=protocol.VERSION,
            tick=tick,
            t=round(tick * 0.1, 6),
            robots=poses,
            radio=protocol.RadioCounters(),
            rejected=0,
            stalls=0,
        )
    )
    key = follower.keys.of(keyspace.STATE)
    return Heard(keyspace.STATE, key, payload, KEYRING.seal(names.WORLD, key, payload))


def test_an_old_world_state_replayed_is_refused_and_counted(follower: Follower) -> None:
    assert follower.take(state(follower, 100, 0.0), KEYRING)
    assert follower.take(state(follower, 200, 0.0), KEYRING)
    assert follower.take(state(follower, 200, 0.0), KEYRING)  # the last one again: harmless
    for tick, x in ((100, 0.5), (150, -0.5)):  # old ones, with other poses
        assert not follower.take(state(follower, tick, x), KEYRING)
    assert follower.run.rejected == 2
    assert follower.run.last_state is not None and follower.run.last_state.tick == 200
    assert follower.run.sim_time == pytest.approx(20.0)
    assert follower.take(state(follower, 210, 0.0), KEYRING)  # the world goes on

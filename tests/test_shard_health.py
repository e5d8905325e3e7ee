"""Which shards are up: a shard goes down when its actor is not alive or a call fails, comes
back only once its restarted actor answers as before, and a query needing a down shard is
refused with a retry time (or told to restart the server when it will not come back)."""

import time
from pathlib import Path

import pytest

from viewdb.errors import ShardUnavailable
from viewdb.shards.health import ShardHealth


def _wait(condition, seconds=5.0):
    deadline = time.monotonic() + seconds
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)
    return condition()


def test_a_restarting_shard_is_down_until_its_actor_answers_as_before():
    files = [Path(f"shard-{i:03d}.viewdb") for i in range(3)]
    health = ShardHealth(files, retry_after=2.0)
    states = ["ALIVE"] * 3
    answers: list[str | None] = [None] * 3
    health.watch(lambda i: states[i], lambda i: answers[i], interval=0.01)
    try:
        health.require([0, 1, 2])
        states[1] = "RESTARTING"
        assert _wait(lambda: not health.snapshot()[1].up)
        with pytest.raises(ShardUnavailable, match=r"shard 1 is down \(its actor is restarting\).*retry in 2 s") as exc:
            health.require([0, 1])
        assert exc.value.retry_after == 2.0 and exc.value.path == "shard-001.viewdb"
        health.require([0, 2])  # queries not needing it go on

        answers[1] = "its file changed while it was down: restart the server"
        states[1] = "ALIVE"  # alive again, but not answering as before: stays down, saying why
        assert _wait(lambda: health.snapshot()[1].reason.startswith("its file changed"))
        assert not health.snapshot()[1].up
        answers[1] = None
        assert _wait(lambda: health.snapshot()[1].up)
        status = health.snapshot()[1]
        assert status.recoveries == 1 and len(status.gaps) == 1 and status.gaps[0] > 0
        health.require([0, 1, 2])

        sent = time.monotonic() - 60  # a call sent to the actor that died before shard 1 came back
        health.down(1, "did not answer (ActorDiedError)", sent=sent)
        assert health.snapshot()[1].up  # its failure says nothing of the restarted actor

        health.down(2, "did not answer (ActorDiedError)")  # a failed call marks it down at once
        assert not health.snapshot()[2].up and health.snapshot()[2].to_dict()["restarting"] is True
        states[2] = "DEAD"  # killed for good: no retry time
        assert _wait(lambda: health.snapshot()[2].final)
        with pytest.raises(ShardUnavailable, match="shard 2 is down for good .* restart the server") as exc:
            health.require([2])
        assert exc.value.retry_after is None
    finally:
        health.stop()

"""``python -m deploy.viewer.live``: the live page of one run (started by ``swarm run --view``).

A process of the run like the recorder: it subscribes to the keys the page needs
(``world/state``, ``world/clock``, ``robot/*/status``, ``radio/rx/*``), declares its
liveliness token ``alive/viewer/0`` once its server listens, and serves the page
(``deploy.viewer.server``). At the end the launcher sends the run summary to the
``viewer/finish`` queryable (``--await-finish``); the bridge shows how the run ended, makes
sure every page was sent that last frame, then answers. In a keyed run only the launcher's
query counts (tagged with its key, as for the recorder's ``recorder/finish``); any other is
refused and counted. Started by hand, the run's ending (``world/ending``) does the same
with the summary it carries, and the page exits with the run's exit code. Stopped by a
signal instead, it tells the pages that the run stopped.

It listens, and says one thing the world hears: the page's pause, play and speed
(``viewer/pace``, tagged with the view's key). A run started with ``--hold`` (``swarm run
--view``, unless ``--no-wait``) waits at tick 0 until the first page connects, then plays.
In lockstep pacing changes only when ticks close, so the view cannot change a decision.
The swarm's curves for the page's charts come from a ``FrameCollector`` the observer
feeds (swarm rows only), kept as a bounded ``Series``.
Zenoh callbacks pass every sample through ``deploy.viewer.core.decode.decode_sample``, the
key table's gate, which checks its tag against the run's keys (``swarm run`` hands the view
the run secret, like the recorder) before it decodes anything, and feed the run's observer
(``world_server/observer/observer.py``), which keeps the latest of each robot (and a bounded
list of radio deliveries): the page needs the current state, not a history, so a slow page
or a busy machine never makes a queue grow.
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import contextlib
import json
import logging
import queue
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from bestofn_swarm.plumbing import cliargs, process_main
from bestofn_swarm.plumbing.ending import hear_ending
from bestofn_swarm.plumbing.inbox import BoundedInbox, message_bytes
from bestofn_swarm.wire import auth, keyspace, names, protocol
from bestofn_swarm.wire.names import Role
from deploy.viewer.core import model
from deploy.viewer.core.decode import InvalidSampleError, decode_sample
from deploy.viewer.core.series import Series
from deploy.viewer.options import VIEW_PORT
from deploy.viewer.server import ViewServer
from world_server.core.body import EPUCK
from world_server.core.layout import make_layout
from world_server.core.pooling import Pooling
from world_server.observer.frame import FrameCollector
from world_server.observer.observer import RunObserver

log = logging.getLogger("viewer")

MAX_DELIVERIES = 2000  # radio deliveries kept between two frames; older ones are dropped
FLUSH_TIMEOUT = 2.0  # wall seconds to get the last frame to every page
DEFAULT_NICENESS = 10  # like the recorder: nothing waits for the view
# Finish queries waiting for the page's loop, at most (only the launcher's counts; the
# rest are refused, and those beyond this at once).
FINISH_QUERY_BYTES = 2**20
# Wall seconds after which a play that the world's clock has not followed is said again
# (a put the world missed, before its subscription reached the router).
PACE_AGAIN_AFTER = 2.0
# The speeds a page offers in lockstep (sim seconds per wall second; None: as fast as the
# swarm answers).
SPEEDS: tuple[float | None, ...] = (None, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)


class LiveSource:
    """The run as the page sees it: the run's observer, fed what Zenoh brings. Zenoh
    threads call ``take``; the server's loop calls ``frame``; one lock guards the observer
    and what else they share."""

    def __init__(
        self,
        scene: model.Scene,
        keys: keyspace.Keys,
        keyring: auth.Keyring | None,
        *,
        pace: Callable[[protocol.Pace], None] | None = None,
        held: bool = False,
        lockstep: bool = True,
    ) -> None:
        """``pace``: publishes a ``protocol.Pace`` to the world (None: the page cannot
        pace the run); ``held``: the world waits at tick 0 for the first page."""
        self.scene = scene
        self.keys = keys
        self.keyring = keyring  # None: an unauthenticated run (no tags to check)
        layout = scene.layout
        self.collector = FrameCollector(
            len(layout.sites), layout.best_site, robot_rows=False, keep=False
        )
        self.series = Series()
        self.run = RunObserver(
            range(scene.robots), poolings=True, open_roster=True, series=self.collector
        )
        self._pace = pace
        self.held = held  # until the first page connects
        self.lockstep = lockstep
        self.playing = not held
        self.speed: float | None = None  # None: as fast as the swarm answers (lockstep)
        self._paced_at: tuple[float, int] | None = None  # (wall time, tick) of the last play
        self.poolings: collections.deque[Pooling] = collections.deque(maxlen=1000)
        self.rejected = 0
        self.ended: dict[str, Any] | None = None
        self._first_clock_wall: float | None = None
        self._lock = threading.Lock()
        # The radio deliveries since the last frame, at most MAX_DELIVERIES (sender, receiver).
        self._deliveries: collections.deque[tuple[str, int]] = collections.deque(
            maxlen=MAX_DELIVERIES
        )

    def take(self, key: str, payload: bytes, attachment: bytes | None) -> None:
        """One sample from Zenoh (any thread)."""
        try:
            opened = decode_sample(self.keys, key, payload, attachment, keyring=self.keyring)
            if opened is None:
                return
            with self._lock:
                self._keep(opened)
        except InvalidSampleError as error:
            self.refuse(str(error))

    def refuse(self, reason: str) -> None:
        """Count a sample or query that is not drawn; the first is logged."""
        with self._lock:
            self.rejected += 1
            first = self.rejected == 1
        if first:
            log.warning("refused a sample or query (logged once): %s", reason[:300])

    def _keep(self, opened: keyspace.Opened) -> None:
        """Feed the observer (under the lock). Poolings are counted in order here, not at
        frame time, so that none is missed when several statuses of one robot arrive
        between two frames."""
        run = self.run
        if opened.kind is keyspace.CLOCK and self._first_clock_wall is None:
            self._first_clock_wall = time.monotonic()
        if opened.kind is keyspace.RADIO_RX and opened.robot is not None:
            meta = opened.meta
            self._deliveries.append((meta.sender, opened.robot))
            run.delivery(opened.robot, meta.sender, meta.tick * self._dt())
            return
        noted = run.take(opened)
        if noted.pooling is not None:
            self.poolings.append(noted.pooling)
        if opened.kind is keyspace.STATE:
            self.series.extend(self.collector.take()[1])

    def _dt(self) -> float:
        clock = self.run.last_clock
        return clock.t / clock.tick if clock is not None and clock.tick else 0.1

    def finish(self, summary: dict[str, Any] | None, fallback: str = "stopped") -> None:
        with self._lock:
            if self.ended is None:
                self.ended = model.ending(summary, fallback)
            self.collector.finish()  # the run's last samples, for the charts
            self.series.extend(self.collector.take()[1])

    # --- pacing ------------------------------------------------------------------------

    def _send_pace(self) -> None:
        """Tell the world the page's pause, play and speed."""
        if self._pace is None:
            return
        clock = self.run.last_clock
        self._paced_at = (time.monotonic(), clock.tick if clock is not None else 0)
        self._pace(protocol.Pace(v=protocol.VERSION, playing=self.playing, speed=self.speed))

    def page_connected(self) -> None:
        """The first page to connect starts a held run."""
        with self._lock:
            if self.held and self.ended is None:
                self.held = False
                self.playing = True
                log.info("a page connected: the run goes on")
                self._send_pace()

    def _tend_pace(self) -> None:
        """Say play again if the world's clock did not follow it (under the lock)."""
        if not self.playing or self._paced_at is None or self.ended is not None:
            return
        when, tick = self._paced_at
        clock = self.run.last_clock
        if (clock is None or clock.tick <= tick) and time.monotonic() - when > PACE_AGAIN_AFTER:
            self._send_pace()

    # --- FrameSource -----------------------------------------------------------------

    def hello(self) -> dict[str, Any]:
        return self.scene.hello()

    def frame(self) -> dict[str, Any]:
        with self._lock:
            run = self.run
            clock = run.last_clock
            t = clock.t if clock is not None else 0.0
            elapsed = time.monotonic() - self._first_clock_wall if self._first_clock_wall else 0.0
            deliveries = list(self._deliveries)
            self._deliveries.clear()
            self._tend_pace()
            return model.frame(
                self.scene,
                t=t,
                tick=clock.tick if clock is not None else 0,
                robots=model.views_of(run),
                decided=run.decided(),
                counters=run.last_state,
                poolings=list(self.poolings),
                deliveries=deliveries,
                real_time_factor=t / elapsed if elapsed > 0.5 else None,
                ended=self.ended,
                links=dict(run.links),
                extra={
                    "rejected": self.rejected,
                    "pace": {
                        "held": self.held,
                        "playing": self.playing,
                        "speed": self.speed,
                        "can_pace": self._pace is not None,
                        "speeds": list(SPEEDS) if self.lockstep else [],
                    },
                },
            )

    def opinion(self, robot: int) -> dict[str, Any]:
        with self._lock:
            record = self.run.records.get(robot)
            return model.opinion_message(robot, None if record is None else record.status)

    def series_since(self, epoch: int, count: int) -> dict[str, Any] | None:
        with self._lock:
            return self.series.since(epoch, count)

    def command(self, message: dict[str, Any]) -> None:
        """A page's pause, play or speed (a lockstep run's speed: one of ``SPEEDS``)."""
        op = message.get("op")
        with self._lock:
            if self.ended is not None or self._pace is None:
                return
            if op in ("play", "pause"):
                self.playing = op == "play"
                self.held = False
            elif op == "speed" and self.lockstep and message.get("speed") in SPEEDS:
                speed = message["speed"]
                self.speed = None if speed is None else float(speed)
            else:
                return
            self._send_pace()


# --- the process ---------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="deploy.viewer.live",
        description="Serve the live page of one run (the view of swarm run --view).",
    )
    cliargs.add_run_shape(parser, "of the run, for its layout")
    parser.add_argument(
        "--host", default="127.0.0.1", help="address to listen on (default: 127.0.0.1)"
    )
    parser.add_argument(
        "--port",
        type=cliargs.int_range(0, 65535),
        default=VIEW_PORT,
        help=f"TCP port of the page (default: {VIEW_PORT}; 0: any free port)",
    )
    parser.add_argument(
        "--fps",
        type=cliargs.float_range(0.5, 60.0),
        default=10.0,
        help="frames a second sent to each page (default: 10)",
    )
    parser.add_argument(
        "--hold",
        action="store_true",
        help="the run waits at tick 0 for the page: say play when the first page connects",
    )
    parser.add_argument(
        "--niceness",
        type=cliargs.int_range(0, 19),
        default=DEFAULT_NICENESS,
        help=f"how much to lower this process's CPU priority (default: {DEFAULT_NICENESS})",
    )
    parser.add_argument(
        "--await-finish",
        action="store_true",
        help="show how the run ended only when the launcher's finish query comes (swarm run, "
        "which hands the page its own summary), and serve until stopped; by default the "
        "run's ending does, and the page then exits",
    )
    cliargs.add_zenoh_options(parser)
    cliargs.add_log_level(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    begun = process_main.begin(
        "viewer",
        parser,
        argv,
        process_main.no_settings,
        runs_cores=False,
        # It checks the world's and every robot's tags: only the secret gives all their keys.
        needs_secret="the view",
        lower_priority=True,
    )
    args = begun.args
    try:
        return asyncio.run(_serve(args, begun.keyring, begun.keys))
    except OSError as error:  # the port is taken, or the host is not an address here
        print(f"viewer: cannot serve on {args.host}:{args.port}: {error}", file=sys.stderr)
        return 1


async def _serve(
    args: argparse.Namespace, keyring: auth.Keyring | None, keys: keyspace.Keys
) -> int:
    import zenoh

    from bestofn_swarm.plumbing.world_info import fetch_world_info
    from bestofn_swarm.plumbing.zenoh_session import open_from_args

    layout = make_layout(args.sites, args.robots, args.seed)
    try:
        session = open_from_args(args)
    except zenoh.ZError as error:
        print(f"viewer: cannot open Zenoh session: {error}", file=sys.stderr)
        return 1
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(signum, stop.set)
    finish_queries: BoundedInbox[Any] = BoundedInbox(FINISH_QUERY_BYTES)
    query_came = asyncio.Event()
    endings: list[protocol.RunEnding] = []
    ending_came = asyncio.Event()

    def on_ending(ending: protocol.RunEnding) -> None:
        endings.append(ending)
        loop.call_soon_threadsafe(ending_came.set)

    with session:
        lockstep = True
        try:
            info = fetch_world_info(session, keys, 10.0, keyring, names.VIEWER)
            robot_radius = info.robot_radius
            lockstep = info.clock == "lockstep"
        except TimeoutError as error:
            log.warning("%s; drawing robots at the e-puck's size", error)
            robot_radius = EPUCK.radius
        scene = model.Scene(args.run_id, args.seed, args.robots, layout, robot_radius)
        pace_key = keys.of(keyspace.PACE)

        def pace(message: protocol.Pace) -> None:
            from bestofn_swarm.plumbing.zenoh_session import reliable_put

            payload = protocol.encode(message)
            attachment = auth.seal(keyring, names.VIEWER, pace_key, payload)
            with contextlib.suppress(zenoh.ZError):
                reliable_put(session, pace_key, payload, attachment)

        source = LiveSource(scene, keys, keyring, pace=pace, held=args.hold, lockstep=lockstep)

        def on_sample(sample: Any) -> None:
            attachment = sample.attachment
            source.take(
                str(sample.key_expr),
                sample.payload.to_bytes(),
                attachment.to_bytes() if attachment is not None else None,
            )

        subscribers = [
            session.declare_subscriber(key, on_sample)
            for key in (
                keys.of(keyspace.STATE),
                keys.of(keyspace.CLOCK),
                keys.of(keyspace.STATUS, "*"),
                keys.of(keyspace.RADIO_RX, "*"),
                keys.of(keyspace.LINK, "*"),
            )
        ]

        def on_finish(query: Any) -> None:
            payload = query.payload.to_bytes() if query.payload is not None else b""
            attachment = query.attachment.to_bytes() if query.attachment is not None else None
            size = message_bytes(payload, attachment, keys.of(keyspace.VIEWER_FINISH))
            if finish_queries.put(query, size):
                loop.call_soon_threadsafe(query_came.set)
            else:
                source.refuse(
                    f"{keys.of(keyspace.VIEWER_FINISH)}: no room for another finish query"
                )
                query.reply_err(b"the view has no room for the query")
                query.drop()

        queryable = session.declare_queryable(keys.of(keyspace.VIEWER_FINISH), on_finish)
        # A launcher finishes the page with its own summary (--await-finish); by hand, the
        # run's ending does, and the page exits with the run's exit code.
        hearing = None if args.await_finish else hear_ending(session, keys, keyring, on_ending)
        server = ViewServer(source, fps=args.fps)
        port = await server.start(args.host, args.port)
        token = session.liveliness().declare_token(keys.token(Role.VIEWER, 0))
        log.info("serving the live view on http://%s:%d/", args.host, port)
        finisher = asyncio.create_task(
            _finish_on_query(finish_queries, query_came, source, server, keys)
        )
        stop_waiter = asyncio.create_task(stop.wait())
        ending_waiter = asyncio.create_task(ending_came.wait())
        await asyncio.wait(
            {finisher, stop_waiter, ending_waiter}, return_when=asyncio.FIRST_COMPLETED
        )
        if endings and not finisher.done():  # the run ended: the page shows how, and goes
            finisher.cancel()
            source.finish(endings[0].summary, fallback="ended")
            await server.flushed(server.publish(), FLUSH_TIMEOUT)
        elif not finisher.done():  # stopped by a signal before the launcher's summary came
            finisher.cancel()
            source.finish(None)
            await server.flushed(server.publish(), FLUSH_TIMEOUT)
        if not endings:
            await stop.wait()  # after the summary, the launcher stops the view once it is done
        ending_waiter.cancel()
        stop_waiter.cancel()
        if hearing is not None:
            hearing.undeclare()
        token.undeclare()
        queryable.undeclare()
        for subscriber in subscribers:
            subscriber.undeclare()
        await server.close()
    if source.rejected:
        log.info("refused %d samples or queries in all", source.rejected)
    return endings[0].code if endings else 0


async def _next_query(queries: BoundedInbox[Any], came: asyncio.Event) -> Any:
    """The next finish query, once the Zenoh callback that queued it said so."""
    while True:
        try:
            return queries.get(timeout=0)
        except queue.Empty:
            came.clear()
        await came.wait()


async def _finish_on_query(
    queries: BoundedInbox[Any],
    came: asyncio.Event,
    source: LiveSource,
    server: ViewServer,
    keys: keyspace.Keys,
) -> None:
    """Show how the run ended when the launcher says so; refuse (and count) anyone else."""
    key = keys.of(keyspace.VIEWER_FINISH)
    while True:
        query = await _next_query(queries, came)
        payload = query.payload.to_bytes() if query.payload is not None else b""
        attachment = query.attachment.to_bytes() if query.attachment is not None else None
        try:
            asker, nonce = auth.query_open(source.keyring, key, payload, attachment)
            if source.keyring is not None and asker != names.LAUNCHER:
                raise auth.AuthError(f"{asker} may not end the view")
        except auth.AuthError as error:
            source.refuse(f"{key}: finish query refused: {error}")
            query.reply_err(b"unauthenticated query")
            query.drop()
            continue
        break
    summary: dict[str, Any] | None = None
    with contextlib.suppress(ValueError):
        value = json.loads(payload) if payload else None
        summary = value if isinstance(value, dict) else None
    source.finish(summary, fallback="ended")
    await server.flushed(server.publish(), FLUSH_TIMEOUT)
    answer = b"ok"
    query.reply(key, answer, attachment=auth.reply_seal(source.keyring, asker, key, answer, nonce))
    query.drop()


if __name__ == "__main__":
    process_main.end(main())

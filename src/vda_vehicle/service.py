"""The vehicle service: N simulated vehicles, one MQTT session each, one shared tick loop.

Lifecycle: every session connects with its own last will (CONNECTIONBROKEN, 3.0
CONNECTION_BROKEN) and publishes ONLINE,
factsheet and state after every (re)connect. One tick task drives all vehicles of the process at
``tick_hz`` with ``dt = time_lapse × elapsed``. :meth:`VehicleService.stop` publishes OFFLINE
(QoS 1, retained) on every session, then disconnects cleanly (R10).
"""

from __future__ import annotations

import asyncio
import gc
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Final

import structlog

from vda5050.clock import Clock, SystemClock
from vda5050.codec import HeaderStamper
from vda5050.collector import FULL_COLLECTION_EVERY_S, tuned_collector
from vda5050.graph_file import GraphFile
from vda5050.models import ConnectionState
from vda5050.mqtt import (
    ConnectedHook,
    InboundMessage,
    MessageHandler,
    MqttSession,
    Outgoing,
)
from vda5050.topics import AgvId, Topic
from vda_vehicle.capabilities import Capabilities
from vda_vehicle.config import Placement, VehicleSettings, capabilities, placements
from vda_vehicle.maps import initial_maps
from vda_vehicle.model import VehicleState
from vda_vehicle.navigation import SimulatedStack
from vda_vehicle.runtime import Metrics, Timing, VehicleRuntime
from vda_vehicle.runtime3 import VehicleRuntimeV3

if TYPE_CHECKING:
    from vda_vehicle.control import ControlServer

log = structlog.get_logger()
#: Vehicles ticked together; a fleet is ticked in slices of this size spread over the period.
SLICE: Final = 100


#: Event times this close to a scheduled one are the same event (recomputed on a later tick).
EVENT_SLACK_S: Final = 1e-3


@dataclass
class _Vehicle:
    runtime: VehicleRuntime
    session: MqttSession
    #: When the timer for the vehicle's next event fires (None: no timer).
    event_at: float | None = None


class VehicleService:
    """Runs the vehicles of one process until :meth:`stop`."""

    def __init__(
        self,
        settings: VehicleSettings,
        graph: GraphFile | None = None,
        *,
        clock: Clock | None = None,
    ) -> None:
        self.settings = settings
        self.metrics = Metrics()
        self._clock = clock or SystemClock()
        self._stopping = asyncio.Event()
        self._deferred = DeferredStates(self._clock)
        self._timing = Timing(
            state_interval_s=settings.state_interval_s,
            visualization_interval_s=settings.visualization_interval_s,
            tick_s=1.0 / settings.tick_hz,
            time_lapse=settings.time_lapse,
        )
        caps = capabilities(settings, graph)
        self._stack = SimulatedStack(caps.speed_max_mps, caps.angular_speed_max_radps)
        self.vehicles = [self._vehicle(p, caps) for p in placements(settings, graph)]
        self.runtimes = [vehicle.runtime for vehicle in self.vehicles]
        self.control = self._control_server()

    def _control_server(self) -> ControlServer | None:
        """The operator-event API (:mod:`vda_vehicle.control`) if ``control_port`` is set;
        imported only then (FastAPI and uvicorn are not the vehicles' start-up)."""
        if self.settings.control_port is None:
            return None
        from vda_vehicle.control import ControlServer  # noqa: PLC0415

        return ControlServer(
            self.runtimes,
            host=self.settings.control_host,
            port=self.settings.control_port,
            key=self.settings.control_key,
        )

    def _vehicle(self, placement: Placement, caps: Capabilities) -> _Vehicle:
        agv = AgvId(self.settings.manufacturer, placement.serial_number)
        runtime_class = VehicleRuntimeV3 if self.settings.speaks_v3 else VehicleRuntime
        runtime = runtime_class(
            agv=agv,
            state=VehicleState(
                pose=placement.pose,
                last_node_id=placement.last_node_id,
                maps=initial_maps(caps.map_ids),
                battery_charge=self.settings.battery_start_pct,
            ),
            caps=caps,
            stack=self._stack,
            stamper=HeaderStamper(agv, self.settings.vda_version, self._clock),
            interface_name=self.settings.topic_interface_name,
            timing=self._timing,
            clock=self._clock,
            metrics=self.metrics,
        )
        default_id = f"{self.settings.topic_interface_name}-{agv.manufacturer}-{agv.serial_number}"
        mqtt = self.settings.mqtt_settings(client_id=default_id)
        if self.settings.client_id and self.settings.count > 1:
            # One client id per connection: a configured id becomes a prefix with --count.
            mqtt = replace(mqtt, client_id=f"{self.settings.client_id}-{agv.serial_number}")
        session = MqttSession(
            mqtt,
            will=runtime.will,
            on_connected=_hook(runtime),
            on_access_changed=runtime.set_broker_problems,
            name=f"vehicle.{agv.serial_number}",
        )
        # Denied publications are loud: the ONLINE and the first state must come back (issue 14).
        session.verify_echo(runtime.topics[Topic.CONNECTION])
        session.verify_echo(runtime.topics[Topic.STATE])
        qos = self.settings.qos
        inbound: dict[Topic, Callable[[str, bytes], None]] = {
            Topic.ORDER: runtime.handle_order,
            Topic.INSTANT_ACTIONS: runtime.handle_instant_actions,
        }
        if isinstance(runtime, VehicleRuntimeV3):  # 3.0 §4.3: zoneSet; responses answer requests
            inbound[Topic.ZONE_SET] = runtime.handle_zone_set
            inbound[Topic.RESPONSES] = runtime.handle_responses
        for kind, take in inbound.items():
            session.subscribe(runtime.topics[kind], _handler(runtime, take, self._deferred), qos)
        return _Vehicle(runtime, session)

    async def run(self) -> None:
        """Serve until :meth:`stop`; every task is a named child of one TaskGroup."""
        count = len(self.vehicles)
        interval = self._timing.visualization_interval_s
        shutdowns: set[asyncio.Task[None]] = set()
        for index, vehicle in enumerate(self.vehicles):
            vehicle.runtime.attach(
                vehicle.session.publish, visualization_offset_s=interval * index / count
            )
            vehicle.runtime.on_next_event(self._event_timer(vehicle))
            if isinstance(vehicle.runtime, VehicleRuntimeV3):
                vehicle.runtime.on_shutdown(self._shutdown_hook(vehicle, shutdowns))
        log.info("vehicles.started", count=count, broker=self.settings.broker_url)
        async with asyncio.TaskGroup() as group:
            for vehicle in self.vehicles:
                name = f"vehicle.{vehicle.runtime.agv.serial_number}.session"
                group.create_task(vehicle.session.run(), name=name)
            ticker = group.create_task(self._tick_loop(), name="vehicle.tick_loop")
            if self.control is not None:
                group.create_task(self.control.serve(), name="vehicle.control_api")
            await self._stopping.wait()
            ticker.cancel()
            if self.control is not None:
                self.control.close()
            await asyncio.gather(*(self._stop_session(v) for v in self.vehicles))
        log.info("vehicles.stopped", count=count)

    async def wait_connected(self) -> None:
        """Return once every vehicle's session is connected (bound it with asyncio.timeout)."""
        await asyncio.gather(*(v.session.wait_connected() for v in self.vehicles))

    def stop(self) -> None:
        """Ask :meth:`run` to publish OFFLINE everywhere, disconnect and return."""
        self._stopping.set()

    def _shutdown_hook(
        self, vehicle: _Vehicle, tasks: set[asyncio.Task[None]]
    ) -> Callable[[], None]:
        """3.0 ``shutdown`` (T07): the vehicle publishes OFFLINE and disconnects; the others
        go on. Nothing over MQTT starts it again (a restart of the process does)."""

        def shut_down() -> None:
            name = f"vehicle.{vehicle.runtime.agv.serial_number}.shutdown"
            task = asyncio.get_running_loop().create_task(self._stop_session(vehicle), name=name)
            tasks.add(task)
            task.add_done_callback(tasks.discard)

        return shut_down

    async def _stop_session(self, vehicle: _Vehicle) -> None:
        runtime = vehicle.runtime
        offline = Outgoing(
            runtime.topics[Topic.CONNECTION],
            Topic.CONNECTION,
            lambda: runtime.connection_payload(ConnectionState.OFFLINE),
        )
        await vehicle.session.stop(offline)

    async def _tick_loop(self) -> None:
        """Drive every vehicle at tick_hz, in slices of at most SLICE vehicles spread over the
        tick period, so events wait for one slice rather than the whole fleet (R93, R94).

        A late slice is measured; missed slices are skipped, not caught up. While it runs, the
        cyclic garbage collector is tuned (:mod:`vda5050.collector`), so that full collections
        of a thousand vehicles' objects do not stall ticks at random.
        """
        clock = self._clock
        slices = max(1, math.ceil(len(self.runtimes) / SLICE))
        groups = [self.runtimes[index::slices] for index in range(slices)]
        period = self._timing.tick_s / slices
        scheduled = clock.monotonic()
        last = [scheduled] * slices
        next_full_gc = scheduled + FULL_COLLECTION_EVERY_S
        with tuned_collector():
            for index in itertools.cycle(range(slices)):
                scheduled += period
                await asyncio.sleep(max(0.0, scheduled - clock.monotonic()))
                now = clock.monotonic()
                self.metrics.tick_lateness_s.append(now - scheduled)
                dt = (now - last[index]) * self.settings.time_lapse
                last[index] = now
                for runtime in groups[index]:
                    runtime.tick_to(now, dt)
                if now >= next_full_gc:
                    gc.collect()
                    next_full_gc = now + FULL_COLLECTION_EVERY_S
                if clock.monotonic() - scheduled > period:
                    scheduled = clock.monotonic()

    def _event_timer(self, vehicle: _Vehicle) -> Callable[[float], None]:
        """A node reached between two ticks is reported when it is reached (R93), not up to a
        tick period later: one timer per vehicle, at the time its runtime announces."""
        loop = asyncio.get_running_loop()
        clock = self._clock

        def fire(at: float) -> None:
            if vehicle.event_at != at:  # superseded by a later announcement
                return
            vehicle.event_at = None
            vehicle.runtime.tick_event(max(clock.monotonic(), at))

        def schedule(at: float) -> None:
            if vehicle.event_at is not None and abs(vehicle.event_at - at) < EVENT_SLACK_S:
                return
            vehicle.event_at = at
            loop.call_later(max(0.0, at - clock.monotonic()), fire, at)

        return schedule


class DeferredStates:
    """Sends the states that R94 deferred as soon as minStateInterval allows.

    A state asked for by a message (an order, instant actions) within minStateInterval of the
    last one is deferred; the vehicle's next full tick would send it, up to a tick later, so
    an order arriving just after a state was acknowledged a tick late. One timer per vehicle.
    """

    def __init__(self, clock: Clock) -> None:
        self._clock = clock
        self._waiting: set[int] = set()

    def schedule(self, runtime: VehicleRuntime) -> None:
        due = runtime.deferred_state_due()
        if due is None or id(runtime) in self._waiting:
            return
        self._waiting.add(id(runtime))
        delay = max(0.0, due - self._clock.monotonic())
        asyncio.get_running_loop().call_later(delay, self._send, runtime)

    def _send(self, runtime: VehicleRuntime) -> None:
        self._waiting.discard(id(runtime))
        runtime.send_deferred_state()


def _hook(runtime: VehicleRuntime) -> ConnectedHook:
    async def on_connected() -> None:
        runtime.on_connected()

    return on_connected


def _handler(
    runtime: VehicleRuntime, take: Callable[[str, bytes], None], deferred: DeferredStates
) -> MessageHandler:
    """An inbound topic's handler: ``take`` (one of the runtime's ``handle_*``) under the
    vehicle's log context, then the state it may owe is scheduled."""

    async def handle(message: InboundMessage) -> None:
        with structlog.contextvars.bound_contextvars(agv=str(runtime.agv)):
            take(message.topic, message.payload)
        deferred.schedule(runtime)

    return handle

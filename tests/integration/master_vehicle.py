"""A scripted test vehicle for master-control integration tests.

It speaks VDA 5050 over a real MqttSession (last will, ONLINE, retained factsheet, states) and
follows a deliberately simple script: accept new orders and stitched updates, drive one released
node per ``step_s``, finish node actions at once, honour cancelOrder. Knobs make it drop the first
orders (a lossy QoS 0 link), reject every order, or report another operating mode.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING

from vda5050.clock import SystemClock
from vda5050.codec import HeaderStamper, decode_as, encode
from vda5050.models import (
    ActionState,
    ActionStatus,
    AgvPosition,
    Connection,
    ConnectionState,
    Edge,
    EdgeState,
    Error,
    ErrorLevel,
    ErrorReference,
    InstantActions,
    Node,
    NodeState,
    OperatingMode,
    Order,
)
from vda5050.mqtt import InboundMessage, MqttSession, MqttSettings, Will
from vda5050.testing import make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.graph import Graph
from vda_master.testing import make_factsheet

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress


class ScriptedVehicle:
    """One simulated vehicle; run it with :func:`running_vehicle`."""

    def __init__(
        self,
        address: BrokerAddress,
        interface_name: str,
        graph: Graph,
        *,
        serial: str = "robot_1",
        start_node: str = "7",
        version: str = "2.1.0",
        step_s: float = 0.02,
        drop_orders: int = 0,
        reject: bool = False,
        mode: OperatingMode = OperatingMode.AUTOMATIC,
        with_factsheet: bool = True,
    ) -> None:
        self.agv = AgvId("acme", serial)
        self.interface_name = interface_name
        self.graph = graph
        self.version = version
        self.step_s = step_s
        self.drop_orders = drop_orders
        self.reject = reject
        self.mode = mode
        self.with_factsheet = with_factsheet
        self.stamper = HeaderStamper(self.agv, version, SystemClock())
        self.order_id, self.update_id = "", 0
        self.last_node, self.last_seq = start_node, 0
        self.nodes: list[Node] = []
        self.edges: list[Edge] = []
        self.actions: dict[str, tuple[str, ActionStatus]] = {}
        self.errors: list[Error] = []
        self.received: list[Order] = []
        self.instant: list[InstantActions] = []
        self.new_base_request = False
        self.moved = asyncio.Event()
        settings = MqttSettings(url=address.url, client_id=f"{interface_name}-{serial}")
        self.session = MqttSession(
            settings, will=self._will(), on_connected=self._on_connected, name=serial
        )
        self.session.subscribe(self._topic(Topic.ORDER), self._on_order)
        self.session.subscribe(self._topic(Topic.INSTANT_ACTIONS), self._on_instant_actions)

    # -- publishing ------------------------------------------------------------------------

    def _topic(self, kind: Topic) -> str:
        return build_topic(self.interface_name, 2, self.agv, kind)

    def _connection(self, state: ConnectionState) -> Connection:
        return Connection(
            header_id=0,
            timestamp="2026-01-01T00:00:00.000Z",
            version=self.version,
            manufacturer=self.agv.manufacturer,
            serial_number=self.agv.serial_number,
            connection_state=state,
        )

    def _will(self) -> Will:
        broken = self.stamper.stamp(
            Topic.CONNECTION, self._connection(ConnectionState.CONNECTIONBROKEN)
        )
        return Will(self._topic(Topic.CONNECTION), encode(broken))

    async def _on_connected(self) -> None:
        online = self._connection(ConnectionState.ONLINE)
        self.session.publish(
            self._topic(Topic.CONNECTION),
            Topic.CONNECTION,
            lambda: encode(self.stamper.stamp(Topic.CONNECTION, online)),
        )
        if self.with_factsheet:
            sheet = make_factsheet(
                version=self.version,
                manufacturer=self.agv.manufacturer,
                serial_number=self.agv.serial_number,
                default_state_interval=30.0,
            )
            self.session.publish(
                self._topic(Topic.FACTSHEET),
                Topic.FACTSHEET,
                lambda: encode(self.stamper.stamp(Topic.FACTSHEET, sheet)),
            )
        self.publish_state()

    def publish_state(self) -> None:
        """Publish the current state (stamped when really sent)."""
        node = self.graph.nodes[self.last_node]
        state = make_state(
            version=self.version,
            manufacturer=self.agv.manufacturer,
            serial_number=self.agv.serial_number,
            order_id=self.order_id,
            order_update_id=self.update_id,
            last_node_id=self.last_node,
            last_node_sequence_id=self.last_seq,
            node_states=[
                NodeState(node_id=n.node_id, sequence_id=n.sequence_id, released=n.released)
                for n in self.nodes
            ],
            edge_states=[
                EdgeState(edge_id=e.edge_id, sequence_id=e.sequence_id, released=e.released)
                for e in self.edges
            ],
            action_states=[
                ActionState(action_id=i, action_type=t, action_status=s)
                for i, (t, s) in self.actions.items()
            ],
            errors=list(self.errors),
            operating_mode=self.mode,
            new_base_request=self.new_base_request,
            driving=bool(self.edges and self.edges[0].released),
            agv_position=AgvPosition(
                x=node.x, y=node.y, theta=0.0, map_id="demo", position_initialized=True
            ),
        )
        self.session.publish(
            self._topic(Topic.STATE),
            Topic.STATE,
            lambda: encode(self.stamper.stamp(Topic.STATE, state)),
        )

    # -- order handling --------------------------------------------------------------------

    async def _on_order(self, message: InboundMessage) -> None:
        order = decode_as(Order, Topic.ORDER, message.payload)
        assert isinstance(order, Order), order
        self.received.append(order)
        if self.drop_orders > 0:
            self.drop_orders -= 1
            return
        if self.reject:
            self.errors.append(_rejection(order))
        elif order.order_id != self.order_id:
            self._accept_new(order)
        elif order.order_update_id > self.update_id:
            self._accept_update(order)
        else:
            return  # R45: the same update again is discarded silently
        self.publish_state()

    def _accept_new(self, order: Order) -> None:
        self.order_id, self.update_id = order.order_id, order.order_update_id
        first = order.nodes[0]
        self.last_node, self.last_seq = first.node_id, first.sequence_id
        self.nodes, self.edges = list(order.nodes[1:]), list(order.edges)
        self.actions = {}
        for actions in [*(n.actions for n in order.nodes), *(e.actions for e in order.edges)]:
            for action in actions:
                self.actions[action.action_id] = (action.action_type, ActionStatus.WAITING)
        self._finish_actions(first)
        self.errors = []

    def _accept_update(self, order: Order) -> None:
        stitch = order.nodes[0].sequence_id
        self.update_id = order.order_update_id
        self.nodes = [n for n in self.nodes if n.sequence_id <= stitch and n.released]
        self.edges = [e for e in self.edges if e.sequence_id < stitch and e.released]
        self.nodes += order.nodes[1:]
        self.edges += order.edges
        for actions in [*(n.actions for n in order.nodes[1:]), *(e.actions for e in order.edges)]:
            for action in actions:
                self.actions[action.action_id] = (action.action_type, ActionStatus.WAITING)
        self.new_base_request = False
        self.moved.set()

    def _finish_actions(self, node: Node) -> None:
        for action in node.actions:
            self.actions[action.action_id] = (action.action_type, ActionStatus.FINISHED)

    async def _on_instant_actions(self, message: InboundMessage) -> None:
        batch = decode_as(InstantActions, Topic.INSTANT_ACTIONS, message.payload)
        assert isinstance(batch, InstantActions), batch
        self.instant.append(batch)
        for action in batch.actions:
            status = ActionStatus.FINISHED
            if action.action_type == "cancelOrder":
                status = self._cancel()
            self.actions[action.action_id] = (action.action_type, status)
        self.publish_state()

    def _cancel(self) -> ActionStatus:
        if not self.nodes and not self.edges:
            return ActionStatus.FAILED
        self._clear_order()
        return ActionStatus.FINISHED

    def _clear_order(self) -> None:
        """Stop where it stands: empty node and edge states, waiting actions FAILED; orderId,
        orderUpdateId and lastNodeId kept (3.0 §6.6.7)."""
        self.nodes, self.edges = [], []
        for action_id, (kind, status) in self.actions.items():
            if status == ActionStatus.WAITING:
                self.actions[action_id] = (kind, ActionStatus.FAILED)

    def switch_mode(self, mode: OperatingMode) -> None:
        """An operator switches the vehicle's operatingMode; entering or leaving MANUAL clears
        the order (2.x §6.10.6 Table 1)."""
        if OperatingMode.MANUAL in (mode, self.mode):
            self._clear_order()
        self.mode = mode
        self.publish_state()

    # -- driving ---------------------------------------------------------------------------

    async def drive_loop(self) -> None:
        """Traverse one released node per step; ask for more base at the decision point."""
        while True:
            await asyncio.sleep(self.step_s)
            if self.nodes and self.nodes[0].released and self.edges and self.edges[0].released:
                self.edges.pop(0)
                node = self.nodes.pop(0)
                self.last_node, self.last_seq = node.node_id, node.sequence_id
                self._finish_actions(node)
                self.publish_state()
            elif self.nodes and not self.new_base_request:
                self.new_base_request = True
                self.publish_state()


def _rejection(order: Order) -> Error:
    refs = [("orderId", order.order_id), ("orderUpdateId", str(order.order_update_id))]
    return Error(
        error_type="orderError",
        error_level=ErrorLevel.WARNING,
        error_description="scripted rejection",
        error_references=[ErrorReference(reference_key=k, reference_value=v) for k, v in refs],
    )


@asynccontextmanager
async def running_vehicle(vehicle: ScriptedVehicle) -> AsyncIterator[ScriptedVehicle]:
    """Run ``vehicle`` (MQTT session and drive loop) for the duration of the block."""
    async with asyncio.TaskGroup() as group:
        group.create_task(vehicle.session.run(), name=f"test.{vehicle.agv.serial_number}")
        driver = group.create_task(vehicle.drive_loop(), name="test.drive_loop")
        async with asyncio.timeout(5):
            await vehicle.session.wait_connected()
        try:
            yield vehicle
        finally:
            driver.cancel()
            await vehicle.session.stop()

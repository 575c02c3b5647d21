"use strict";
// A vda-5050-lib MasterController driven by JSON-line commands on stdin.
//
// Usage: node master.js '{"brokerUrl": "mqtt://127.0.0.1:1883", "interfaceName": "uagv",
//                         "vdaVersion": "2.0.0"}'
// Commands (one JSON object per stdin line; "id" is echoed in the answer):
//   {"id": "1", "cmd": "order", "agv": {"manufacturer": M, "serialNumber": S}, "order": {...}}
//       the order without header fields; assigned with MasterController.assignOrder
//   {"id": "2", "cmd": "instantActions", "agv": {...}, "actions": [{actionId, actionType,
//       blockingType, actionParameters?}, ...]}   sent with initiateInstantActions, which in 2.0.0
//       puts the array under the key "instantActions" (the library's dialect)
//   {"id": "3", "cmd": "cancel", "agv": {...}, "actionId": "c1"}   a cancelOrder instant action
// Stdout, one JSON line per event (see jsonl.js): ready; sent {id, topic, message} (the message
// as published, header included) or command_failed {id, message}; connection; state (every
// received state, in full); factsheet; order_processed {orderId, orderUpdateId, error,
// byCancelation, active, state}; node_traversed; edge_traversed; order_action_state; instant_action_state
// {actionId, actionType, actionStatus, error}; instant_action_error; peer_error; stopped.

const readline = require("readline");
const { MasterController, Topic } = require("vda-5050-lib");
const { emit, readConfig, onTerminate } = require("./jsonl");

function agvOf(context) {
    return { manufacturer: context.agvId.manufacturer, serialNumber: context.agvId.serialNumber };
}

function orderEvents(order) {
    const ids = { orderId: order.orderId, orderUpdateId: order.orderUpdateId };
    return {
        // context.state is the state that completed the order (the "state" line follows it).
        onOrderProcessed: (error, byCancelation, active, context) => emit("order_processed", { ...ids, agv: agvOf(context), error: error || null, byCancelation, active, state: context.state }),
        onNodeTraversed: (node, nextEdge, nextNode, context) => emit("node_traversed", { ...ids, agv: agvOf(context), nodeId: node.nodeId, sequenceId: node.sequenceId }),
        onEdgeTraversed: (edge, startNode, endNode, context) => emit("edge_traversed", { ...ids, agv: agvOf(context), edgeId: edge.edgeId, sequenceId: edge.sequenceId }),
        onActionStateChanged: (actionState, error, action, target, context) => emit("order_action_state", { ...ids, agv: agvOf(context), ...actionState, error: error || null }),
    };
}

const instantActionEvents = {
    onActionStateChanged: (actionState, error, action, agvId) => emit("instant_action_state", { agv: agvId, ...actionState, error: error || null }),
    onActionError: (error, action, agvId) => emit("instant_action_error", { agv: agvId, actionId: action.actionId, actionType: action.actionType, error }),
};

async function run(controller, command) {
    switch (command.cmd) {
        case "order":
            return [Topic.Order, await controller.assignOrder(command.agv, command.order, orderEvents(command.order))];
        case "instantActions":
            return [Topic.InstantActions, await controller.initiateInstantActions(command.agv, { instantActions: command.actions }, instantActionEvents)];
        case "cancel": {
            const cancel = { actionId: command.actionId, actionType: "cancelOrder", blockingType: "HARD" };
            return [Topic.InstantActions, await controller.initiateInstantActions(command.agv, { instantActions: [cancel] }, instantActionEvents)];
        }
        default:
            throw new Error(`unknown command ${JSON.stringify(command.cmd)}`);
    }
}

async function main() {
    const config = readConfig();
    const controller = new MasterController({
        interfaceName: config.interfaceName,
        transport: { brokerUrl: config.brokerUrl },
        vdaVersion: config.vdaVersion || "2.0.0",
    }, { targetAgvs: {} });
    onTerminate(() => controller.stop());
    await controller.start();
    controller.trackAgvs((agvId, connectionState) => emit("connection", { agv: agvId, connectionState }));
    await controller.subscribe(Topic.State, {}, (state, agvId) => emit("state", { agv: agvId, state }));
    await controller.subscribe(Topic.Factsheet, {}, (factsheet, agvId) => emit("factsheet", { agv: agvId, factsheet }));
    const lines = readline.createInterface({ input: process.stdin });
    lines.on("line", async line => {
        let command = {};
        try {
            command = JSON.parse(line);
            const [topic, message] = await run(controller, command);
            emit("sent", { id: command.id, topic, message: message || null });
        } catch (error) {
            emit("command_failed", { id: command.id, message: String(error && error.message || error) });
        }
    });
    emit("ready");
}

main().catch(error => {
    emit("peer_error", { message: `start failed: ${error && error.stack || error}` });
    process.exit(1);
});

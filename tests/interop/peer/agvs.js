"use strict";
// Virtual AGVs of vda-5050-lib (AgvController + VirtualAgvAdapter), one per serial number.
//
// Usage: node agvs.js '<json config>' with
//   {"brokerUrl": "mqtt://127.0.0.1:1883", "interfaceName": "uagv", "manufacturer": "vdalib",
//    "vdaVersion": "2.0.0",
//    "agvs": [{"serialNumber": "agv_1",
//              "position": {"x": 0, "y": 0, "theta": 0, "mapId": "m", "lastNodeId": "n1"}}],
//    "timeLapse": 1, "tickRate": 5, "vehicleSpeed": 2, "stateIntervalS": 30,
//    "visualizationIntervalS": 1, "deviationXyTolerance": 0.5,
//    "initialBatteryCharge": 100, "fullBatteryChargeTime": 1}
// Everything but brokerUrl, interfaceName, manufacturer and agvs is optional (library defaults).
// No factsheet is configured: the library's AGV then answers factsheetRequest with an empty one.
//
// Stdout, one JSON line per event (see jsonl.js): ready, state (every published state, in full),
// order_accepted, node_reached, action_state, error_reported (every new entry of state.errors),
// factsheet, connection, publish_failed, peer_error, stopped.

const { AgvController, VirtualAgvAdapter, Topic } = require("vda-5050-lib");
const { emit, readConfig, onTerminate } = require("./jsonl");

// Watches what the controller publishes (AgvClient.publish is public API) and reports changes.
class ObservedAgvController extends AgvController {
    async publish(topic, object, options) {
        let published;
        try {
            published = await super.publish(topic, object, options);
        } catch (error) {
            emit("publish_failed", { serialNumber: this.agvId.serialNumber, topic, message: String(error.message || error) });
            throw error;
        }
        if (published !== undefined) {
            this._report(topic, published);
        }
        return published;
    }

    _report(topic, message) {
        const serialNumber = this.agvId.serialNumber;
        if (topic === Topic.State) {
            emit("state", { serialNumber, state: message });
            this._reportStateChanges(message);
        } else if (topic === Topic.Factsheet) {
            emit("factsheet", { serialNumber, factsheet: message });
        } else if (topic === Topic.Connection) {
            emit("connection", { serialNumber, connectionState: message.connectionState });
        }
    }

    _reportStateChanges(state) {
        const serialNumber = this.agvId.serialNumber;
        const seen = this._seen || (this._seen = { order: "", node: "", actions: new Map(), errors: new Set() });
        const order = `${state.orderId}/${state.orderUpdateId}`;
        if (state.orderId && order !== seen.order) {
            emit("order_accepted", { serialNumber, orderId: state.orderId, orderUpdateId: state.orderUpdateId });
        }
        seen.order = order;
        const node = `${state.lastNodeId}/${state.lastNodeSequenceId}`;
        if (node !== seen.node) {
            emit("node_reached", { serialNumber, nodeId: state.lastNodeId, sequenceId: state.lastNodeSequenceId, agvPosition: state.agvPosition });
        }
        seen.node = node;
        for (const action of state.actionStates) {
            if (seen.actions.get(action.actionId) !== action.actionStatus) {
                seen.actions.set(action.actionId, action.actionStatus);
                emit("action_state", { serialNumber, ...action });
            }
        }
        const errors = new Set(state.errors.map(e => JSON.stringify(e)));
        for (const error of errors) {
            if (!seen.errors.has(error)) {
                const parsed = JSON.parse(error);
                const topicRef = (parsed.errorReferences || []).find(r => r.referenceKey === "topic");
                emit("error_reported", { serialNumber, topic: topicRef ? topicRef.referenceValue : null, error: parsed });
            }
        }
        seen.errors = errors;
    }
}

function adapterOptions(config, agv) {
    const options = { initialPosition: agv.position };
    const names = {
        timeLapse: "timeLapse", tickRate: "tickRate", vehicleSpeed: "vehicleSpeed",
        deviationXyTolerance: "agvNormalDeviationXyTolerance",
        initialBatteryCharge: "initialBatteryCharge", fullBatteryChargeTime: "fullBatteryChargeTime",
    };
    for (const [key, option] of Object.entries(names)) {
        if (config[key] !== undefined) {
            options[option] = config[key];
        }
    }
    return options;
}

function controllerOptions(config) {
    const options = { agvAdapterType: VirtualAgvAdapter };
    if (config.stateIntervalS !== undefined) {
        options.publishStateInterval = config.stateIntervalS * 1000;
    }
    if (config.visualizationIntervalS !== undefined) {
        options.publishVisualizationInterval = config.visualizationIntervalS * 1000;
    }
    return options;
}

async function main() {
    const config = readConfig();
    const clientOptions = {
        interfaceName: config.interfaceName,
        transport: { brokerUrl: config.brokerUrl },
        vdaVersion: config.vdaVersion || "2.0.0",
    };
    const controllers = config.agvs.map(agv => new ObservedAgvController(
        { manufacturer: config.manufacturer, serialNumber: agv.serialNumber },
        clientOptions,
        controllerOptions(config),
        adapterOptions(config, agv),
    ));
    onTerminate(() => Promise.all(controllers.map(c => c.stop())));
    await Promise.all(controllers.map(c => c.start()));
    for (const controller of controllers) {
        emit("ready", { serialNumber: controller.agvId.serialNumber });
    }
}

main().catch(error => {
    emit("peer_error", { message: `start failed: ${error && error.stack || error}` });
    process.exit(1);
});

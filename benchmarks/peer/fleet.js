"use strict";
// The peer side of benchmarks/fleet.py: vda-5050-lib's MasterController and N virtual AGVs
// (AgvController + VirtualAgvAdapter) in this one Node process, on one broker.
//
// Usage: node fleet.js '<json config>' with
//   {"brokerUrl": "mqtt://127.0.0.1:1883", "interfaceName": "fleet", "manufacturer": "peer",
//    "vehicles": 100, "laneSpacing": 3, "edgeLength": 8, "speed": 2, "timeLapse": 1,
//    "visualizationIntervalS": 1, "orders": true}
// AGV i (serial "peer-<i+1>") stands at (0, i * laneSpacing) on node "a<i>" and, once every AGV
// is available and a line arrives on stdin, gets one order a<i> -> b<i> -> c<i> along +x, the whole order released.
//
// Stdout, one JSON line per event ({"event", "t": unix seconds, ...}): master_started (the
// moment the AGVs are started), available (the master has a state of every AGV), orders_start,
// order_sent
// {serialNumber, callS} per order (callS: how long assignOrder took), orders_sent, processed
// {serialNumber, error}, all_processed, peer_error, stopped.

const { AgvController, MasterController, VirtualAgvAdapter, Topic } = require("vda-5050-lib");

function emit(event, fields = {}) {
    process.stdout.write(JSON.stringify({ event, t: Date.now() / 1000, ...fields }) + "\n");
}

console.error = (...args) => emit("peer_error", { message: args.map(String).join(" ") });
process.on("unhandledRejection", error => emit("peer_error", { message: `unhandled rejection: ${error && error.stack || error}` }));

function lane(config, index) {
    const y = index * config.laneSpacing;
    const mapId = "fleet";
    const node = (name, k) => ({
        nodeId: `${name}${index}`,
        sequenceId: 2 * k,
        released: true,
        nodePosition: { x: k * config.edgeLength, y, mapId },
        actions: [],
    });
    const nodes = [node("a", 0), node("b", 1), node("c", 2)];
    const edge = (k) => ({
        edgeId: `e${k + 1}_${index}`,
        sequenceId: 2 * k + 1,
        released: true,
        startNodeId: nodes[k].nodeId,
        endNodeId: nodes[k + 1].nodeId,
        maxSpeed: config.speed,
        actions: [],
    });
    return { start: { x: 0, y, theta: 0, mapId, lastNodeId: nodes[0].nodeId }, nodes, edges: [edge(0), edge(1)] };
}

async function main() {
    const config = JSON.parse(process.argv[2]);
    const clientOptions = {
        interfaceName: config.interfaceName,
        transport: { brokerUrl: config.brokerUrl },
        vdaVersion: "2.0.0",
    };
    const master = new MasterController(clientOptions, { targetAgvs: {} });
    await master.start();
    const seen = new Set();
    let resolveAvailable;
    const available = new Promise(resolve => { resolveAvailable = resolve; });
    await master.subscribe(Topic.State, {}, (state, agvId) => {
        if (!seen.has(agvId.serialNumber)) {
            seen.add(agvId.serialNumber);
            if (seen.size === config.vehicles) {
                resolveAvailable();
            }
        }
    });
    const lanes = [];
    const controllers = [];
    for (let i = 0; i < config.vehicles; i++) {
        lanes.push(lane(config, i));
        controllers.push(new AgvController(
            { manufacturer: config.manufacturer, serialNumber: `${config.manufacturer}-${i + 1}` },
            clientOptions,
            { agvAdapterType: VirtualAgvAdapter, publishVisualizationInterval: config.visualizationIntervalS * 1000 },
            { initialPosition: lanes[i].start, timeLapse: config.timeLapse, vehicleSpeed: config.speed },
        ));
    }
    const stop = async () => {
        await Promise.all(controllers.map(c => c.stop()));
        await master.stop();
        emit("stopped");
        process.exit(0);
    };
    process.on("SIGTERM", stop);
    process.on("SIGINT", stop);
    emit("master_started");
    await Promise.all(controllers.map(c => c.start()));
    await available;
    emit("available");
    if (!config.orders) {
        return;
    }
    await new Promise(resolve => process.stdin.once("data", resolve));  // "go" from the benchmark
    emit("orders_start");
    let processed = 0;
    await Promise.all(controllers.map(async (controller, i) => {
        const agv = { manufacturer: config.manufacturer, serialNumber: controller.agvId.serialNumber };
        const order = { orderId: `order-${i}`, orderUpdateId: 0, nodes: lanes[i].nodes, edges: lanes[i].edges };
        const begin = process.hrtime.bigint();
        await master.assignOrder(agv, order, {
            onOrderProcessed: (error) => {
                emit("processed", { serialNumber: agv.serialNumber, error: error ? String(error) : null });
                processed += 1;
                if (processed === config.vehicles) {
                    emit("all_processed");
                }
            },
        });
        emit("order_sent", { serialNumber: agv.serialNumber, callS: Number(process.hrtime.bigint() - begin) / 1e9 });
    }));
    emit("orders_sent");
}

main().catch(error => {
    emit("peer_error", { message: `start failed: ${error && error.stack || error}` });
    process.exit(1);
});

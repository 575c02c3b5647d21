"use strict";
// Shared by the interop peers: one JSON object per stdout line, and a clean stop on SIGTERM.
//
// Every line is {"event": <name>, "t": <unix seconds>, ...fields}. The library reports messages
// it drops (schema-invalid inbound messages) with console.error; those become "peer_error" lines
// so that the Python side sees them instead of losing them in stderr.

const util = require("util");

function emit(event, fields = {}) {
    process.stdout.write(JSON.stringify({ event, t: Date.now() / 1000, ...fields }) + "\n");
}

console.error = (...args) => emit("peer_error", { message: util.format(...args) });

function readConfig() {
    const raw = process.argv[2];
    if (!raw) {
        process.stderr.write("usage: node <peer>.js '<json config>'\n");
        process.exit(2);
    }
    return JSON.parse(raw);
}

// Runs `stop` once on SIGTERM/SIGINT, then exits 0 ("stopped" line) or 1 ("stop_failed").
function onTerminate(stop) {
    let stopping = false;
    const handler = async () => {
        if (stopping) {
            return;
        }
        stopping = true;
        try {
            await stop();
            emit("stopped");
            process.exit(0);
        } catch (error) {
            emit("stop_failed", { message: String(error && error.message || error) });
            process.exit(1);
        }
    };
    process.on("SIGTERM", handler);
    process.on("SIGINT", handler);
}

process.on("unhandledRejection", error => emit("peer_error", { message: `unhandled rejection: ${error && error.stack || error}` }));
process.on("uncaughtException", error => {
    emit("peer_error", { message: `uncaught exception: ${error && error.stack || error}` });
    process.exit(1);
});

module.exports = { emit, readConfig, onTerminate };

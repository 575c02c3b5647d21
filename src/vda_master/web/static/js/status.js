// A vehicle's condition on the map: the one place that maps what the master knows to a colour.
// First match wins (docs/web.md, "Status"):
//   offline  connection not ONLINE (OFFLINE, CONNECTIONBROKEN, never seen), no state yet, or
//            silent longer than the master's unreachable limit
//   error    a FATAL error in its state
//   estop    an emergency stop is active (state.safetyState.eStop not NONE)
//   outofservice  an operator took it out of service (inService false): master control
//            sends it no order until it is put back
//   manual   an operatingMode master control does not drive in (MANUAL, SERVICE, TEACHIN; a 3.0
//            robot's INTERVENED and STARTUP arrive as MANUAL and SERVICE)
//   paused   state.paused
//   waiting  traffic control says it waits for another vehicle (waitingFor not empty)
//   driving  state.driving
//   busy     an order or an action is still under way (nodes/edges left, action running)
//   idle     none of the above

export const STATUSES = [
  "idle", "driving", "busy", "waiting", "paused", "manual", "outofservice", "estop", "error",
  "offline",
];

export const STATUS_LABELS = {
  idle: "idle",
  driving: "driving",
  busy: "busy (order or action)",
  waiting: "waiting in traffic",
  paused: "paused",
  manual: "not in master control's hands (MANUAL, SERVICE, TEACHIN; 3.0 INTERVENED, STARTUP)",
  outofservice: "out of service (taken out by an operator)",
  estop: "emergency stop",
  error: "error (FATAL)",
  offline: "offline / connection broken",
};

const RUNNING = new Set(["INITIALIZING", "RUNNING", "PAUSED"]);
const CONTROLLED = new Set(["AUTOMATIC", "SEMIAUTOMATIC"]);

export function vehicleStatus(vehicle, traffic, nowS) {
  if (vehicle.connection !== "ONLINE" || !vehicle.hasState) return "offline";
  if (nowS - vehicle.lastStateWall > vehicle.unreachableAfterS) return "offline";
  if (vehicle.errors.some((e) => e.errorLevel === "FATAL")) return "error";
  if (vehicle.eStop && vehicle.eStop !== "NONE") return "estop";
  if (vehicle.inService === false) return "outofservice";
  if (vehicle.operatingMode && !CONTROLLED.has(vehicle.operatingMode)) return "manual";
  if (vehicle.paused) return "paused";
  if (traffic && traffic.waitingFor && traffic.waitingFor.length > 0) return "waiting";
  if (vehicle.driving) return "driving";
  const underway = vehicle.nodeStates.length > 0 || vehicle.edgeStates.length > 0 ||
    vehicle.actionStates.some((a) => RUNNING.has(a.actionStatus));
  return underway ? "busy" : "idle";
}

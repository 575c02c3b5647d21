// What is drawn for the selected vehicle: the rest of its order along the graph (base solid,
// horizon dashed, from its state's nodeStates/edgeStates released flags, §6.10.6), the resources
// traffic control reserved for it, and arrows to the vehicles it waits for.

import { clear, edgeShape, lineAttrs, svgEl, sx, sy } from "./svg.js";

export function drawOverlay(layers, nodes, store, vehicle) {
  clear(layers.route);
  clear(layers.holds);
  clear(layers.waits);
  if (!vehicle) return;
  drawRoute(layers.route, nodes, vehicle, store);
  const traffic = store.trafficOf(vehicle.id);
  if (traffic) drawTraffic(layers, nodes, store, vehicle, traffic);
}

// Where a node of the order lies: the graph's node, else the position the state gives.
function nodePoint(nodes, nodeState) {
  const node = nodes.get(nodeState.nodeId);
  if (node) return node;
  return nodeState.x === null ? null : { x: nodeState.x, y: nodeState.y };
}

function drawRoute(layer, nodes, vehicle, store) {
  const ordered = [...vehicle.nodeStates].sort((a, b) => a.sequenceId - b.sequenceId);
  const edgeStates = new Map(vehicle.edgeStates.map((e) => [e.sequenceId, e]));
  const graphEdges = new Map((store.graph?.edges || []).map((entry) => [entry[0], entry]));
  let previous = vehicle.x === null ? null : { x: vehicle.x, y: vehicle.y };
  let fromNode = false; // previous is a node of the order (not the vehicle's own position)
  for (const nodeState of ordered) {
    const point = nodePoint(nodes, nodeState);
    if (!point) continue;
    const edgeState = edgeStates.get(nodeState.sequenceId - 1);
    const kind = (edgeState?.released ?? nodeState.released) ? "base" : "horizon";
    const entry = edgeState && graphEdges.get(edgeState.edgeId);
    if (previous && fromNode && entry) {
      const [shape, attrs] = edgeShape(entry, previous, point);
      svgEl(shape, { class: kind, ...attrs }, layer);
    } else if (previous) {
      svgEl("line", { class: kind, ...lineAttrs(previous, point) }, layer);
    }
    previous = point;
    fromNode = true;
  }
  for (const nodeState of ordered) {
    const point = nodePoint(nodes, nodeState);
    if (!point) continue;
    svgEl("circle", { class: nodeState.released ? "base" : "horizon", r: 0.14,
      cx: sx(point.x), cy: sy(point.y), "data-route-node": nodeState.nodeId }, layer);
  }
}

function drawTraffic(layers, nodes, store, vehicle, traffic) {
  const edges = new Map((store.graph?.edges || []).map((entry) => [entry[0], entry]));
  for (const hold of traffic.holds || []) {
    const [kind, id] = splitResource(hold);
    if (kind === "node" && nodes.has(id)) {
      const n = nodes.get(id);
      svgEl("circle", { r: 0.55, cx: sx(n.x), cy: sy(n.y), "data-hold": hold }, layers.holds);
    } else if (kind === "edge" && edges.has(id)) {
      const entry = edges.get(id);
      const [a, b] = [nodes.get(entry[1]), nodes.get(entry[2])];
      if (!a || !b) continue;
      const [shape, attrs] = edgeShape(entry, a, b);
      svgEl(shape, { "data-hold": hold, ...attrs }, layers.holds);
    }
  }
  const [, at] = splitResource(traffic.waitingAt || "");
  if (nodes.has(at)) {
    const n = nodes.get(at);
    svgEl("circle", { r: 0.7, cx: sx(n.x), cy: sy(n.y) }, layers.waits);
  }
  for (const other of traffic.waitingFor || []) {
    const blocker = store.vehicles.get(other);
    if (!blocker || blocker.x === null || vehicle.x === null) continue;
    svgEl("line", { "data-waits-for": other, ...lineAttrs(vehicle, blocker, 0, 0.6) }, layers.waits);
  }
}

// "node:A1" -> ["node", "A1"]; an id without a kind is taken as a node.
export function splitResource(resource) {
  const colon = resource.indexOf(":");
  return colon < 0 ? ["node", resource] : [resource.slice(0, colon), resource.slice(colon + 1)];
}

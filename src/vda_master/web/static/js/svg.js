// Small SVG helpers. Map coordinates are metres with y up; SVG's y points down, so y is negated
// and angles (counter-clockwise in the map) turn clockwise on screen.

export const SVG_NS = "http://www.w3.org/2000/svg";

export function svgEl(name, attrs = {}, parent = null) {
  const node = document.createElementNS(SVG_NS, name);
  for (const [key, value] of Object.entries(attrs)) node.setAttribute(key, value);
  if (parent) parent.appendChild(node);
  return node;
}

export const sx = (x) => x;
export const sy = (y) => -y;
export const degrees = (theta) => (-theta * 180) / Math.PI;

export function clear(node) {
  while (node.firstChild) node.removeChild(node.firstChild);
}

const round = (v) => Math.round(v * 1000) / 1000;

// A line from a to b ({x, y} in map metres), moved `offset` to its right and shortened by
// `trim` at both ends (so arrowheads stay outside node markers).
export function lineAttrs(a, b, offset = 0, trim = 0) {
  const dx = b.x - a.x;
  const dy = b.y - a.y;
  const length = Math.hypot(dx, dy) || 1;
  const ux = dx / length;
  const uy = dy / length;
  const ox = uy * offset;
  const oy = -ux * offset;
  const cut = Math.min(trim, length / 3);
  return {
    x1: round(sx(a.x + ux * cut + ox)),
    y1: round(sy(a.y + uy * cut + oy)),
    x2: round(sx(b.x - ux * cut + ox)),
    y2: round(sy(b.y - uy * cut + oy)),
  };
}

// A polyline through `points` ([{x, y}, ...] in map metres) as SVG attributes, its first and
// last pieces shortened by `trim` (as lineAttrs does for a straight edge).
export function polylineAttrs(points, trim = 0) {
  const at = points.map((p) => ({ x: p.x, y: p.y }));
  const shorten = (from, to) => {
    const dx = to.x - from.x;
    const dy = to.y - from.y;
    const length = Math.hypot(dx, dy);
    if (!length) return;
    const cut = Math.min(trim, length / 3) / length;
    from.x += dx * cut;
    from.y += dy * cut;
  };
  if (at.length >= 2) {
    shorten(at[0], at[1]);
    shorten(at[at.length - 1], at[at.length - 2]);
  }
  return { points: at.map((p) => `${round(sx(p.x))},${round(sy(p.y))}`).join(" ") };
}

// The shape of a graph edge ([id, start, end, inner?] as the page's graph lists it) from node
// a to node b: a "line" when straight, a "polyline" through its trajectory's points when curved.
export function edgeShape(entry, a, b, offset = 0, trim = 0) {
  const inner = entry[3];
  if (!inner || !inner.length) return ["line", lineAttrs(a, b, offset, trim)];
  const points = [a, ...inner.map(([x, y]) => ({ x, y })), b];
  return ["polyline", polylineAttrs(points, trim)];
}

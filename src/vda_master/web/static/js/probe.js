// Measurements the browser tests and benchmarks/map.py read through window.vdaMap:
// - latency: from the master receiving a vehicle's message (its `rx` stamp, epoch ms) to the
//   first animation frame after the change was written to the DOM (so it has been painted);
// - frame times: requestAnimationFrame deltas over a window.

const KEEP = 20000;

export class Probe {
  constructor() {
    this.latencies = [];
  }

  // Called by the frame that wrote changes received at `stamps` into the DOM.
  painted(stamps) {
    if (!stamps.length) return;
    requestAnimationFrame(() => {
      const now = performance.timeOrigin + performance.now();
      for (const rx of stamps) this.latencies.push(now - rx);
      if (this.latencies.length > KEEP) this.latencies.splice(0, this.latencies.length - KEEP);
    });
  }

  // requestAnimationFrame deltas (ms) over the next `durationMs`.
  frames(durationMs) {
    return new Promise((resolve) => {
      const deltas = [];
      let last = null;
      const end = performance.now() + durationMs;
      const step = (time) => {
        if (last !== null) deltas.push(time - last);
        last = time;
        if (time < end) requestAnimationFrame(step);
        else resolve(deltas);
      };
      requestAnimationFrame(step);
    });
  }
}

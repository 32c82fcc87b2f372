// Replay arithmetic on one car's trace columns (t, x, y, yaw, progress, status, ...):
// laps with sector splits, incidents, and poses interpolated at any time.
"use strict";

const SECTORS = 3;
const INCIDENTS = { off_track: "off", crashed: "crash" };

const Laps = {
  // Index of the last sample at or before time t (-1 before the first sample).
  indexAt(trace, t) {
    const times = trace.t;
    let lo = 0;
    let hi = times.length - 1;
    if (!times.length || t < times[0]) return -1;
    while (lo < hi) {
      const mid = (lo + hi + 1) >> 1;
      if (times[mid] <= t) lo = mid;
      else hi = mid - 1;
    }
    return lo;
  },

  // Pose at time t, interpolated between samples (clamped to the first and last).
  poseAt(trace, t) {
    const n = trace.t.length;
    const i = Laps.indexAt(trace, t);
    if (i < 0) return { x: trace.x[0], y: trace.y[0], yaw: trace.yaw[0], index: 0 };
    if (i >= n - 1) return { x: trace.x[n - 1], y: trace.y[n - 1], yaw: trace.yaw[n - 1], index: n - 1 };
    const span = trace.t[i + 1] - trace.t[i] || 1;
    const f = (t - trace.t[i]) / span;
    let dyaw = trace.yaw[i + 1] - trace.yaw[i];
    dyaw = Math.atan2(Math.sin(dyaw), Math.cos(dyaw));
    return {
      x: trace.x[i] + f * (trace.x[i + 1] - trace.x[i]),
      y: trace.y[i] + f * (trace.y[i + 1] - trace.y[i]),
      yaw: trace.yaw[i] + f * dyaw,
      index: i,
    };
  },

  // Laps as {number, start, end, startIndex, endIndex, sectors: [s1, s2, s3] (seconds)};
  // the last lap has end null when the car did not complete it. Sector k ends where the
  // lap's progress first reaches k/3 (interpolated between samples).
  laps(trace) {
    const laps = [];
    let lap = Laps._newLap(1, 0, 0);
    for (let i = 0; i < trace.t.length; i++) {
      const p = trace.status[i] === "lap_complete" ? 100 : trace.progress[i];
      const prevP = i > lap.startIndex ? trace.progress[i - 1] : 0;
      const prevT = i > 0 ? trace.t[i - 1] : 0;
      while (lap.marks.length < SECTORS - 1 && p >= (100 * (lap.marks.length + 1)) / SECTORS) {
        const target = (100 * (lap.marks.length + 1)) / SECTORS;
        const f = p > prevP ? Math.min(Math.max((target - prevP) / (p - prevP), 0), 1) : 1;
        lap.marks.push(prevT + f * (trace.t[i] - prevT));
      }
      if (trace.status[i] === "lap_complete") {
        Laps._close(lap, trace.t[i], i);
        laps.push(lap);
        lap = Laps._newLap(lap.number + 1, trace.t[i], i + 1);
      }
    }
    if (lap.startIndex < trace.t.length) {
      Laps._close(lap, null, trace.t.length - 1);
      laps.push(lap);
    }
    return laps;
  },

  _newLap(number, start, startIndex) {
    return { number, start, startIndex, end: null, endIndex: null, marks: [], sectors: [] };
  },

  _close(lap, end, endIndex) {
    lap.end = end;
    lap.endIndex = endIndex;
    const bounds = [lap.start, ...lap.marks];
    if (end !== null) bounds.push(end);
    lap.sectors = bounds.slice(1).map((b, k) => b - bounds[k]);
  },

  // The completed lap with the shortest time, or null.
  bestLap(laps) {
    const done = laps.filter((l) => l.end !== null);
    if (!done.length) return null;
    return done.reduce((a, b) => (b.end - b.start < a.end - a.start ? b : a));
  },

  // Off-track and crash incidents: [{t, x, y, kind}] where the status first changed to one.
  incidents(trace) {
    const found = [];
    for (let i = 0; i < trace.status.length; i++) {
      const kind = INCIDENTS[trace.status[i]];
      if (kind && (i === 0 || trace.status[i - 1] !== trace.status[i])) {
        found.push({ t: trace.t[i], x: trace.x[i], y: trace.y[i], kind });
      }
    }
    return found;
  },

  // Seconds after the lap's start at which it reached progress p (interpolated), or null.
  timeAtProgress(trace, lap, p) {
    const last = lap.endIndex === null ? trace.t.length - 1 : lap.endIndex;
    let prevT = lap.start;
    let prevP = 0;
    for (let i = lap.startIndex; i <= last; i++) {
      const q = trace.status[i] === "lap_complete" ? 100 : trace.progress[i];
      if (q >= p) {
        const f = q > prevP ? (p - prevP) / (q - prevP) : 1;
        return prevT + f * (trace.t[i] - prevT) - lap.start;
      }
      prevT = trace.t[i];
      prevP = q;
    }
    return null;
  },

  // Progress (0-100) of the lap at time t, interpolated.
  progressAt(trace, lap, t) {
    const i = Laps.indexAt(trace, t);
    if (i < lap.startIndex) return 0;
    const last = lap.endIndex === null ? trace.t.length - 1 : lap.endIndex;
    if (i >= last) return trace.status[last] === "lap_complete" ? 100 : trace.progress[last];
    const span = trace.t[i + 1] - trace.t[i] || 1;
    const next = trace.status[i + 1] === "lap_complete" ? 100 : trace.progress[i + 1];
    return trace.progress[i] + ((t - trace.t[i]) / span) * (next - trace.progress[i]);
  },
};

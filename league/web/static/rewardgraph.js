// The training reward graph, as DeepRacer's console drew it: average reward (left axis),
// training and evaluation completion (right axis, %), and optionally a marker on the
// iteration whose checkpoint is the model. Used by the model page and the training page.
// `metrics` is {columns, values: {column: [number or null]}} (GET /api/models/{id}/metrics).
"use strict";

const RewardGraph = {
  // Five grid lines labelled from y1 (top) to y0 on the left (and by right(k), k = 0..4,
  // on the right), and the x axis from x0 to x1 with its label.
  axes(ctx, W, H, pad, [y0, y1], [x0, x1], xLabel, right = null) {
    ctx.strokeStyle = "#ccc";
    ctx.fillStyle = "#444";
    ctx.font = "12px system-ui, sans-serif";
    for (let k = 0; k <= 4; k++) {
      const y = pad.t + (k / 4) * (H - pad.t - pad.b);
      ctx.beginPath();
      ctx.moveTo(pad.l, y);
      ctx.lineTo(W - pad.r, y);
      ctx.stroke();
      ctx.textAlign = "right";
      ctx.fillText((y1 - (k / 4) * (y1 - y0)).toFixed(1), pad.l - 6, y + 4);
      if (right) {
        ctx.textAlign = "left";
        ctx.fillText(right(k), W - pad.r + 6, y + 4);
      }
    }
    ctx.textAlign = "center";
    ctx.fillText(xLabel, W / 2, H - 8);
    ctx.fillText(String(x0), pad.l, H - pad.b + 16);
    ctx.fillText(String(x1), W - pad.r, H - pad.b + 16);
  },

  series(metrics, column) {
    const xs = metrics.values.iteration || metrics.values[metrics.columns[0]].map((_, i) => i);
    const ys = metrics.values[column] || [];
    return xs.map((x, i) => [x, ys[i]]).filter(([x, y]) => x !== null && y !== null && y !== undefined);
  },

  // Draw on `canvas`; false when there is nothing to draw. `options.marker`: an iteration
  // to mark with a dashed line and `options.markerLabel`.
  draw(canvas, metrics, options = {}) {
    canvas.hidden = false;
    const ctx = canvas.getContext("2d");
    const W = canvas.width;
    const H = canvas.height;
    const pad = { l: 60, r: 60, t: 20, b: 40 };
    ctx.fillStyle = "#fff";
    ctx.fillRect(0, 0, W, H);
    const reward = RewardGraph.series(metrics, "mean_reward");
    const lines = [
      { data: reward, color: "#1e9e4a", label: "average reward (training)", axis: "left" },
      { data: RewardGraph.series(metrics, "mean_progress"), color: "#2f6fff", label: "average % completion (training)", axis: "right" },
      { data: RewardGraph.series(metrics, "eval_progress"), color: "#e0342b", label: "average % completion (evaluation)", axis: "right", dots: true },
    ];
    const all = lines.flatMap((l) => l.data);
    if (!all.length) return false;
    const x0 = Math.min(...all.map((p) => p[0]));
    const x1 = Math.max(...all.map((p) => p[0])) || 1;
    const r0 = Math.min(0, ...reward.map((p) => p[1]));
    const r1 = Math.max(1, ...reward.map((p) => p[1]));
    const sx = (x) => pad.l + ((x - x0) / (x1 - x0 || 1)) * (W - pad.l - pad.r);
    const sy = {
      left: (y) => H - pad.b - ((y - r0) / (r1 - r0)) * (H - pad.t - pad.b),
      right: (y) => H - pad.b - (y / 100) * (H - pad.t - pad.b),
    };
    RewardGraph.axes(ctx, W, H, pad, [r0, r1], [x0, x1], "iteration", (k) => `${100 - k * 25}%`);
    if (options.marker !== null && options.marker !== undefined) {
      ctx.save();
      ctx.strokeStyle = "#7a3cff";
      ctx.fillStyle = "#7a3cff";
      ctx.setLineDash([5, 4]);
      ctx.beginPath();
      ctx.moveTo(sx(options.marker), pad.t);
      ctx.lineTo(sx(options.marker), H - pad.b);
      ctx.stroke();
      ctx.textAlign = "center";
      ctx.fillText(options.markerLabel || "model", sx(options.marker), H - pad.b - 6);
      ctx.restore();
    }
    lines.forEach((line, n) => RewardGraph.line(ctx, pad, n, line, sx, sy[line.axis], line.dots ? 6 : 0));
    canvas.dataset.points = String(reward.length);
    return true;
  },

  COLORS: ["#1f5fd6", "#e0342b", "#1e9e4a", "#b86e00", "#7a3cff", "#008b8b", "#c2185b", "#5b6470"],

  // Several runs' series on one axis: lines [{data: [[x, y]], label}], each in its own
  // colour with a legend; false when there is nothing to draw.
  plot(canvas, lines, xLabel = "iteration") {
    const ctx = canvas.getContext("2d");
    const W = canvas.width;
    const H = canvas.height;
    const pad = { l: 60, r: 20, t: 20, b: 40 };
    ctx.fillStyle = "#fff";
    ctx.fillRect(0, 0, W, H);
    const all = lines.flatMap((l) => l.data);
    canvas.dataset.lines = String(lines.filter((l) => l.data.length).length);
    if (!all.length) return false;
    const x0 = Math.min(...all.map((p) => p[0]));
    const x1 = Math.max(...all.map((p) => p[0]));
    const y0 = Math.min(...all.map((p) => p[1]));
    const y1 = Math.max(...all.map((p) => p[1]));
    const sx = (x) => pad.l + ((x - x0) / (x1 - x0 || 1)) * (W - pad.l - pad.r);
    const sy = (y) => H - pad.b - ((y - y0) / (y1 - y0 || 1)) * (H - pad.t - pad.b);
    RewardGraph.axes(ctx, W, H, pad, [y0, y1], [x0, x1], xLabel);
    lines.forEach((line, n) => {
      const color = RewardGraph.COLORS[n % RewardGraph.COLORS.length];
      RewardGraph.line(ctx, pad, n, { ...line, color }, sx, sy, 4);
    });
    return true;
  },

  // One series as a line in its colour (dots of `dot` px when non-zero), with its label as
  // the n-th legend row.
  line(ctx, pad, n, line, sx, sy, dot) {
    ctx.strokeStyle = ctx.fillStyle = line.color;
    ctx.lineWidth = 2;
    ctx.beginPath();
    line.data.forEach(([x, y], i) => (i ? ctx.lineTo(sx(x), sy(y)) : ctx.moveTo(sx(x), sy(y))));
    ctx.stroke();
    if (dot) line.data.forEach(([x, y]) => ctx.fillRect(sx(x) - dot / 2, sy(y) - dot / 2, dot, dot));
    ctx.textAlign = "left";
    ctx.fillText(line.label, pad.l + 10, pad.t + 14 + 16 * n);
  },
};

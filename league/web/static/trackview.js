// Drawing a track from its geometry, and cars, obstacles and markers on it, on a canvas.
"use strict";

const CAR_LENGTH = 0.38;
const CAR_WIDTH = 0.2;

class TrackView {
  constructor(canvas, geometry) {
    this.canvas = canvas;
    this.geometry = geometry;
    const ratio = window.devicePixelRatio || 1;
    const width = canvas.clientWidth || canvas.width;
    const height = canvas.clientHeight || canvas.height;
    canvas.width = Math.round(width * ratio);
    canvas.height = Math.round(height * ratio);
    this.ctx = canvas.getContext("2d");
    this.ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    this.width = width;
    this.height = height;
    this._fit();
  }

  // Scale and offset so that both borders fit the canvas with a margin, y pointing up.
  _fit() {
    const points = this.geometry.left.concat(this.geometry.right);
    const xs = points.map((p) => p[0]);
    const ys = points.map((p) => p[1]);
    this.minX = Math.min(...xs);
    this.maxY = Math.max(...ys);
    const spanX = Math.max(...xs) - this.minX || 1;
    const spanY = this.maxY - Math.min(...ys) || 1;
    const margin = 30;
    this.scale = Math.min((this.width - 2 * margin) / spanX, (this.height - 2 * margin) / spanY);
    this.offX = (this.width - spanX * this.scale) / 2;
    this.offY = (this.height - spanY * this.scale) / 2;
  }

  toScreen(x, y) {
    return [this.offX + (x - this.minX) * this.scale, this.offY + (this.maxY - y) * this.scale];
  }

  _path(points, close) {
    const ctx = this.ctx;
    points.forEach((p, i) => {
      const [sx, sy] = this.toScreen(p[0], p[1]);
      if (i === 0) ctx.moveTo(sx, sy);
      else ctx.lineTo(sx, sy);
    });
    if (close) ctx.closePath();
  }

  drawTrack() {
    const ctx = this.ctx;
    const g = this.geometry;
    ctx.fillStyle = "#25382a";
    ctx.fillRect(0, 0, this.width, this.height);
    ctx.beginPath();
    if (g.is_loop) {
      this._path(g.left, true);
      this._path(g.right, true);
    } else {
      this._path(g.left.concat(g.right.slice().reverse()), true);
    }
    ctx.fillStyle = "#3d4147";
    ctx.fill("evenodd");
    ctx.lineWidth = 2;
    ctx.strokeStyle = "#f2f2f2";
    for (const border of [g.left, g.right]) {
      ctx.beginPath();
      this._path(border, g.is_loop);
      ctx.stroke();
    }
    ctx.setLineDash([8, 8]);
    ctx.lineWidth = 1;
    ctx.strokeStyle = "rgba(255, 214, 0, 0.55)";
    ctx.beginPath();
    this._path(g.waypoints, false);
    ctx.stroke();
    ctx.setLineDash([]);
    this._drawStartLine();
  }

  // A chequered start / finish line across the road at the first waypoint.
  _drawStartLine() {
    const ctx = this.ctx;
    const [ax, ay] = this.toScreen(...this.geometry.left[0]);
    const [bx, by] = this.toScreen(...this.geometry.right[0]);
    const squares = 8;
    const nx = (by - ay) / squares;
    const ny = -(bx - ax) / squares;
    for (let k = 0; k < squares; k++) {
      for (let row = 0; row < 2; row++) {
        const x0 = ax + ((bx - ax) * k) / squares + nx * (row - 1) * 0.5;
        const y0 = ay + ((by - ay) * k) / squares + ny * (row - 1) * 0.5;
        ctx.fillStyle = (k + row) % 2 ? "#111" : "#fff";
        ctx.beginPath();
        ctx.moveTo(x0, y0);
        ctx.lineTo(x0 + (bx - ax) / squares, y0 + (by - ay) / squares);
        ctx.lineTo(x0 + (bx - ax) / squares + nx * 0.5, y0 + (by - ay) / squares + ny * 0.5);
        ctx.lineTo(x0 + nx * 0.5, y0 + ny * 0.5);
        ctx.closePath();
        ctx.fill();
      }
    }
  }

  // A car seen from above: body, windscreen towards the nose, optional label.
  drawCar(pose, color, options = {}) {
    const ctx = this.ctx;
    const [sx, sy] = this.toScreen(pose.x, pose.y);
    const length = CAR_LENGTH * this.scale;
    const width = CAR_WIDTH * this.scale;
    ctx.save();
    ctx.globalAlpha = options.alpha ?? 1;
    ctx.translate(sx, sy);
    ctx.rotate(-pose.yaw);
    ctx.fillStyle = color;
    ctx.strokeStyle = "#0b0b0b";
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.roundRect(-length / 2, -width / 2, length, width, width * 0.25);
    ctx.fill();
    ctx.stroke();
    ctx.fillStyle = "rgba(10, 20, 30, 0.75)";
    ctx.fillRect(length * 0.08, -width * 0.32, length * 0.2, width * 0.64);
    ctx.restore();
    if (options.label) {
      ctx.save();
      ctx.globalAlpha = options.alpha ?? 1;
      ctx.font = "600 12px system-ui, sans-serif";
      ctx.textAlign = "center";
      ctx.lineWidth = 3;
      ctx.strokeStyle = "rgba(0, 0, 0, 0.8)";
      ctx.strokeText(options.label, sx, sy - length * 0.7);
      ctx.fillStyle = "#fff";
      ctx.fillText(options.label, sx, sy - length * 0.7);
      ctx.restore();
    }
  }

  // The car's recent path as a fading line.
  drawTrail(points, color) {
    const ctx = this.ctx;
    for (let i = 1; i < points.length; i++) {
      const [ax, ay] = this.toScreen(points[i - 1][0], points[i - 1][1]);
      const [bx, by] = this.toScreen(points[i][0], points[i][1]);
      ctx.globalAlpha = (0.6 * i) / points.length;
      ctx.strokeStyle = color;
      ctx.lineWidth = 3;
      ctx.beginPath();
      ctx.moveTo(ax, ay);
      ctx.lineTo(bx, by);
      ctx.stroke();
    }
    ctx.globalAlpha = 1;
  }

  drawObstacle(box) {
    const [x, y, yaw, length, width] = box;
    const ctx = this.ctx;
    const [sx, sy] = this.toScreen(x, y);
    ctx.save();
    ctx.translate(sx, sy);
    ctx.rotate(-yaw);
    ctx.fillStyle = "#c98b3a";
    ctx.strokeStyle = "#3b2407";
    ctx.lineWidth = 1.5;
    const l = length * this.scale;
    const w = width * this.scale;
    ctx.fillRect(-l / 2, -w / 2, l, w);
    ctx.strokeRect(-l / 2, -w / 2, l, w);
    ctx.restore();
  }

  // Off-track: an amber ring with "!"; crash: a red ring with a cross.
  drawMarker(incident) {
    const ctx = this.ctx;
    const [sx, sy] = this.toScreen(incident.x, incident.y);
    const r = 9;
    ctx.save();
    ctx.lineWidth = 2.5;
    ctx.strokeStyle = incident.kind === "crash" ? "#ff3b3b" : "#ffb020";
    ctx.fillStyle = "rgba(0, 0, 0, 0.55)";
    ctx.beginPath();
    ctx.arc(sx, sy, r, 0, 2 * Math.PI);
    ctx.fill();
    ctx.stroke();
    ctx.beginPath();
    if (incident.kind === "crash") {
      ctx.moveTo(sx - 4, sy - 4);
      ctx.lineTo(sx + 4, sy + 4);
      ctx.moveTo(sx + 4, sy - 4);
      ctx.lineTo(sx - 4, sy + 4);
      ctx.stroke();
    } else {
      ctx.fillStyle = ctx.strokeStyle;
      ctx.font = "bold 13px system-ui, sans-serif";
      ctx.textAlign = "center";
      ctx.textBaseline = "middle";
      ctx.fillText("!", sx, sy + 1);
    }
    ctx.restore();
  }

  // A race event where it happened: an overtake is an upward triangle in the passing car's
  // colour; a contact a diamond in the colour of the car at fault (grey when nobody was),
  // labelled with that car's name.
  drawRaceMark(mark, color, label) {
    const ctx = this.ctx;
    const [sx, sy] = this.toScreen(mark.x, mark.y);
    const r = 8;
    ctx.save();
    ctx.lineWidth = 2;
    ctx.strokeStyle = mark.kind === "contact" ? "#ff3b3b" : "#0b0b0b";
    ctx.fillStyle = color;
    ctx.beginPath();
    if (mark.kind === "overtake") {
      ctx.moveTo(sx, sy - r);
      ctx.lineTo(sx + r, sy + r * 0.7);
      ctx.lineTo(sx - r, sy + r * 0.7);
    } else {
      ctx.moveTo(sx, sy - r);
      ctx.lineTo(sx + r, sy);
      ctx.lineTo(sx, sy + r);
      ctx.lineTo(sx - r, sy);
    }
    ctx.closePath();
    ctx.fill();
    ctx.stroke();
    if (label) {
      ctx.font = "600 11px system-ui, sans-serif";
      ctx.textAlign = "left";
      ctx.textBaseline = "middle";
      ctx.lineWidth = 3;
      ctx.strokeStyle = "rgba(0, 0, 0, 0.8)";
      ctx.strokeText(label, sx + r + 3, sy);
      ctx.fillStyle = "#fff";
      ctx.fillText(label, sx + r + 3, sy);
    }
    ctx.restore();
  }
}

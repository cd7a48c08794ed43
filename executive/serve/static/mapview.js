// The 2D map: the static occupancy grid, the robot's pose and footprint, the planned
// path and the current navigation goal, the lidar scan, the markers the robot has seen
// and the people the navigation stack tracks. Everything is in `map` [m]; the view fits
// the grid (x to the right, y up). Mouse wheel zooms about the pointer, drag pans,
// double-click fits again.

const COLORS = {
  free: [250, 250, 247], occupied: [40, 44, 52], unknown: [200, 203, 208],
  robot: "#1565c0", heading: "#0d47a1", path: "#2e7d32", goal: "#ef6c00", scan: "#d32f2f",
  marker: "#8e24aa", person: "#00897b",
};

export class MapView {
  constructor(canvas, readout) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.readout = readout;
    this.grid = null;       // {width, height, resolution, origin, image: canvas}
    this.pose = null;       // {t, x, y, theta, v, w}
    this.path = [];
    this.goal = null;       // {x, y, theta, label}
    this.scan = null;
    this.markers = [];
    this.people = [];
    this.radius = 0.18;     // footprint radius [m] (status.robot)
    this.zoom = 1;
    this.pan = [0, 0];
    this.dirty = true;
    this.hookMouse();
    const loop = () => {
      if (this.dirty) this.draw();
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  setRobot(robot) {
    if (!robot) return;
    if (typeof robot.footprint_radius === "number") this.radius = robot.footprint_radius;
    this.dirty = true;
  }

  setMap(m) {
    const raw = atob(m.data);
    const img = new ImageData(m.width, m.height);
    for (let row = 0; row < m.height; row++) {
      for (let col = 0; col < m.width; col++) {
        let v = raw.charCodeAt(row * m.width + col);
        if (v > 127) v -= 256;
        const c = v < 0 ? COLORS.unknown : v >= 50 ? COLORS.occupied : COLORS.free;
        const i = ((m.height - 1 - row) * m.width + col) * 4;  // row 0 is at the origin's y: bottom
        img.data[i] = c[0]; img.data[i + 1] = c[1]; img.data[i + 2] = c[2]; img.data[i + 3] = 255;
      }
    }
    const image = document.createElement("canvas");
    image.width = m.width;
    image.height = m.height;
    image.getContext("2d").putImageData(img, 0, 0);
    this.grid = {width: m.width, height: m.height, resolution: m.resolution, origin: m.origin, image};
    this.dirty = true;
  }

  setPose(p) {
    this.pose = p;
    const deg = Math.round(p.theta * 180 / Math.PI) || 0;  // no "-0"
    this.readout.textContent = `x ${p.x.toFixed(2)} m  y ${p.y.toFixed(2)} m  θ ${deg}°  v ${p.v.toFixed(2)} m/s`;
    this.dirty = true;
  }

  // Another run of the service: forget what the last one saw (the map and pose come again).
  reset() {
    this.path = [];
    this.goal = null;
    this.scan = null;
    this.markers = [];
    this.people = [];
    this.dirty = true;
  }

  setPath(points) { this.path = points || []; this.dirty = true; }
  setGoal(goal) { this.goal = goal; this.dirty = true; }
  setScan(scan) { this.scan = scan; this.dirty = true; }
  setMarkers(markers) { this.markers = markers || []; this.dirty = true; }
  setPeople(people) { this.people = people || []; this.dirty = true; }

  // map [m] -> canvas pixels
  transform() {
    const W = this.canvas.width, H = this.canvas.height;
    let x0 = 0, y0 = 0, x1 = 5, y1 = 5;
    if (this.grid) {
      const g = this.grid;
      x0 = g.origin[0]; y0 = g.origin[1];
      x1 = x0 + g.width * g.resolution; y1 = y0 + g.height * g.resolution;
    }
    const base = Math.min((W - 16) / (x1 - x0), (H - 16) / (y1 - y0));
    const s = base * this.zoom;
    const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
    const ox = W / 2 - cx * s + this.pan[0], oy = H / 2 + cy * s + this.pan[1];
    return {s, px: (x) => ox + x * s, py: (y) => oy - y * s, x0, y0, x1, y1};
  }

  hookMouse() {
    const c = this.canvas;
    c.addEventListener("wheel", (ev) => {
      ev.preventDefault();
      const f = ev.deltaY < 0 ? 1.2 : 1 / 1.2;
      const r = c.getBoundingClientRect();
      const mx = (ev.clientX - r.left) * c.width / r.width - c.width / 2 - this.pan[0];
      const my = (ev.clientY - r.top) * c.height / r.height - c.height / 2 - this.pan[1];
      this.pan[0] -= mx * (f - 1);
      this.pan[1] -= my * (f - 1);
      this.zoom *= f;
      this.dirty = true;
    }, {passive: false});
    let drag = null;
    c.addEventListener("mousedown", (ev) => { drag = [ev.clientX, ev.clientY]; });
    window.addEventListener("mouseup", () => { drag = null; });
    c.addEventListener("mousemove", (ev) => {
      if (!drag) return;
      const r = c.getBoundingClientRect();
      this.pan[0] += (ev.clientX - drag[0]) * c.width / r.width;
      this.pan[1] += (ev.clientY - drag[1]) * c.height / r.height;
      drag = [ev.clientX, ev.clientY];
      this.dirty = true;
    });
    c.addEventListener("dblclick", () => { this.zoom = 1; this.pan = [0, 0]; this.dirty = true; });
  }

  draw() {
    this.dirty = false;
    const ctx = this.ctx, T = this.transform();
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = "#e9ebee";
    ctx.fillRect(0, 0, this.canvas.width, this.canvas.height);
    if (this.grid) {
      const g = this.grid;
      ctx.imageSmoothingEnabled = false;
      ctx.drawImage(g.image, T.px(T.x0), T.py(T.y1), (T.x1 - T.x0) * T.s, (T.y1 - T.y0) * T.s);
    } else {
      ctx.fillStyle = "#555";
      ctx.font = "13px sans-serif";
      ctx.fillText("no map yet", 12, 22);
    }
    this.drawPath(T);
    this.drawGoal(T);
    this.drawScan(T);
    this.drawMarkers(T);
    this.drawPeople(T);
    this.drawRobot(T);
  }

  drawPath(T) {
    if (this.path.length < 2) return;
    const ctx = this.ctx;
    ctx.strokeStyle = COLORS.path;
    ctx.lineWidth = 2.5;
    ctx.setLineDash([6, 4]);
    ctx.beginPath();
    this.path.forEach(([x, y], i) => (i ? ctx.lineTo(T.px(x), T.py(y)) : ctx.moveTo(T.px(x), T.py(y))));
    ctx.stroke();
    ctx.setLineDash([]);
  }

  drawGoal(T) {
    const g = this.goal;
    if (!g) return;
    const ctx = this.ctx, x = T.px(g.x), y = T.py(g.y);
    ctx.strokeStyle = COLORS.goal;
    ctx.fillStyle = COLORS.goal;
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.arc(x, y, 6, 0, 2 * Math.PI);
    ctx.stroke();
    ctx.beginPath();
    ctx.moveTo(x, y);
    ctx.lineTo(x + 16 * Math.cos(g.theta), y - 16 * Math.sin(g.theta));
    ctx.stroke();
    if (g.label) {
      ctx.font = "11px sans-serif";
      this.label(g.label, x, y + 14);
    }
  }

  // Text beside the point x, y: to its right, or to its left near the canvas's right edge.
  // `taken`: boxes of labels drawn already; the label moves down a line until it is clear.
  label(text, x, y, taken = []) {
    const w = this.ctx.measureText(text).width, h = 12;
    const lx = x + 8 + w > this.canvas.width - 2 ? x - 8 - w : x + 8;
    let ly = y;
    const clash = (b) => lx < b[0] + b[2] && b[0] < lx + w && ly - h < b[1] && b[1] - h < ly;
    for (let i = 0; i < 6 && taken.some(clash); i++) ly += h;
    taken.push([lx, ly, w]);
    const ctx = this.ctx;
    ctx.save();
    ctx.strokeStyle = "rgba(255, 255, 255, 0.85)";  // a halo: legible over walls and free space
    ctx.lineWidth = 3;
    ctx.lineJoin = "round";
    ctx.strokeText(text, lx, ly);
    ctx.restore();
    ctx.fillText(text, lx, ly);
  }

  drawScan(T) {
    const sc = this.scan;
    if (!sc || !sc.pose) return;
    const p = {x: sc.pose[0], y: sc.pose[1], theta: sc.pose[2]};  // the base when the scan was sent
    const [lx, ly, lyaw] = sc.lidar || [0, 0, 0];
    const c = Math.cos(p.theta), s = Math.sin(p.theta);
    const ox = p.x + c * lx - s * ly, oy = p.y + s * lx + c * ly;
    const ctx = this.ctx;
    ctx.fillStyle = COLORS.scan;
    sc.ranges.forEach((r, i) => {
      if (r === null || r < sc.range_min || r > sc.range_max) return;
      const a = p.theta + lyaw + sc.angle_min + i * sc.angle_increment;
      ctx.fillRect(T.px(ox + r * Math.cos(a)) - 1.5, T.py(oy + r * Math.sin(a)) - 1.5, 3, 3);
    });
  }

  drawMarkers(T) {
    const ctx = this.ctx;
    ctx.font = "bold 11px sans-serif";
    const taken = [];
    for (const m of this.markers) {
      const x = T.px(m.x), y = T.py(m.y);
      ctx.fillStyle = COLORS.marker;
      ctx.fillRect(x - 4, y - 4, 8, 8);
      ctx.strokeStyle = COLORS.marker;
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      ctx.moveTo(x, y);
      ctx.lineTo(x + 12 * Math.cos(m.yaw), y - 12 * Math.sin(m.yaw));
      ctx.stroke();
      this.label(`#${m.id}`, x, y - 6, taken);
    }
  }

  drawPeople(T) {
    const ctx = this.ctx;
    for (const p of this.people) {
      const x = T.px(p.x), y = T.py(p.y);
      ctx.fillStyle = COLORS.person;
      ctx.globalAlpha = 0.35;
      ctx.beginPath();
      ctx.arc(x, y, Math.max(4, 0.25 * T.s), 0, 2 * Math.PI);
      ctx.fill();
      ctx.globalAlpha = 1;
      ctx.strokeStyle = COLORS.person;
      ctx.lineWidth = 2;
      ctx.beginPath();
      ctx.moveTo(x, y);
      ctx.lineTo(T.px(p.x + p.vx), T.py(p.y + p.vy));  // where it will be in 1 s
      ctx.stroke();
    }
  }

  drawRobot(T) {
    const p = this.pose;
    if (!p) return;
    const ctx = this.ctx, x = T.px(p.x), y = T.py(p.y), r = Math.max(3, this.radius * T.s);
    ctx.fillStyle = "rgba(21, 101, 192, 0.25)";
    ctx.strokeStyle = COLORS.robot;
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.arc(x, y, r, 0, 2 * Math.PI);
    ctx.fill();
    ctx.stroke();
    ctx.strokeStyle = COLORS.heading;
    ctx.beginPath();
    ctx.moveTo(x, y);
    ctx.lineTo(x + (r + 6) * Math.cos(p.theta), y - (r + 6) * Math.sin(p.theta));
    ctx.stroke();
  }
}

"""The 3D view of a point cloud: a small offline WebGL viewer written for virtus, with a still
image shown in its place where WebGL is unavailable.

No library and nothing from the network: the page carries the points and about a hundred
lines of WebGL 1 (:data:`VIEWER_JS`: ``gl.POINTS``, drag to orbit, wheel to zoom,
double-click to reset). The cloud is packed small so a 200,000-point view costs about 1.9 MB
of base64:

* positions quantised to ``uint16`` per axis inside the cloud's bounding box (the step is
  the box size / 65535: 3 um for a 0.2 m box, far below the scanner's noise);
* one ``uint8`` colour index per point into a 255-entry table of the quantity's colour map
  (:mod:`virtus.report.figures`), so error and depth keep their colours in 3D; index 255 is
  grey, for points without a value.

Clouds larger than :data:`MAX_POINTS` are subsampled with a seeded generator (same cloud,
same view). Points are in the camera frame (OpenCV: x right, y down, z forward, metres);
the view starts from the camera's side, looking along +z.
"""

from __future__ import annotations

import base64
import json
from dataclasses import dataclass

import numpy as np

from virtus.report.figures import QUANTITIES, _figure, png_bytes

__all__ = ["MAX_POINTS", "VIEWER_JS", "CloudView", "pack_cloud", "still_image"]

#: Most points a view holds; larger clouds are subsampled (seeded).
MAX_POINTS = 200_000
#: Seed of the subsampling generator.
_SEED = 0
#: Colour index of points without a value (e.g. off the fitted sphere), drawn grey.
_NO_VALUE = 255
_NO_VALUE_RGB = (0.62, 0.62, 0.62)


@dataclass(frozen=True)
class CloudView:
    """A packed cloud ready for :data:`VIEWER_JS`.

    Attributes
    ----------
    n_points : points in the view (after subsampling).
    n_total : points of the cloud given (finite ones).
    origin_m, extent_m : (3,) float, the bounding box (camera frame, metres).
    positions_b64 : base64 of (n, 3) uint16 little-endian quantised positions.
    colours_b64 : base64 of (n,) uint8 colour indices.
    palette : 256 ``[r, g, b]`` (0-255): the colour map, then grey for "no value".
    label : what the colours show, with its unit and limits.
    """

    n_points: int
    n_total: int
    origin_m: tuple[float, float, float]
    extent_m: tuple[float, float, float]
    positions_b64: str
    colours_b64: str
    palette: list[list[int]]
    label: str

    def payload(self) -> str:
        """The JSON the viewer script reads (``</`` escaped for an inline script)."""
        data = {
            "n": self.n_points,
            "origin": self.origin_m,
            "extent": self.extent_m,
            "positions": self.positions_b64,
            "colours": self.colours_b64,
            "palette": self.palette,
        }
        return json.dumps(data, separators=(",", ":")).replace("</", "<\\/")


def _subsample(points: np.ndarray, values: np.ndarray, limit: int):
    keep = np.isfinite(points).all(axis=1)
    points, values = points[keep], values[keep]
    if len(points) > limit:
        chosen = np.sort(np.random.default_rng(_SEED).choice(len(points), limit, replace=False))
        points, values = points[chosen], values[chosen]
    return points, values


def pack_cloud(
    points: np.ndarray,
    values: np.ndarray | None,
    quantity: str,
    *,
    limit: int = MAX_POINTS,
    limits: tuple[float, float] | None = None,
) -> CloudView:
    """Pack a cloud for the viewer.

    Parameters
    ----------
    points : (N, 3) float, metres, camera frame; rows with NaN are dropped.
    values : (N,) float, what colours each point (in the quantity's unit; NaN: no value,
        drawn grey), or None to colour by depth (mm).
    quantity : a :data:`~virtus.report.figures.QUANTITIES` name (colour map and label).
    limit : most points kept (seeded subsample beyond).
    limits : colour limits; default 0.5-99.5 percentiles (symmetric quantities: +-99.5th
        percentile of the magnitude).
    """
    from matplotlib import colormaps

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if values is None:
        values, quantity = points[:, 2] * 1000.0, "depth"
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    total = int(np.isfinite(points).all(axis=1).sum())
    points, values = _subsample(points, values, limit)
    spec = QUANTITIES[quantity]
    finite = values[np.isfinite(values)]
    if limits is None and len(finite):
        if spec.symmetric:
            bound = float(np.percentile(np.abs(finite), 99.5)) or 1.0
            limits = (-bound, bound)
        else:
            low, high = np.percentile(finite, [0.5, 99.5])
            limits = (float(low), float(high) if high > low else float(low) + 1.0)
    limits = limits or (0.0, 1.0)
    origin = points.min(axis=0) if len(points) else np.zeros(3)
    extent = np.maximum(points.max(axis=0) - origin, 1e-9) if len(points) else np.ones(3)
    quantised = np.round((points - origin) / extent * 65535.0).astype("<u2")
    scaled = (values - limits[0]) / (limits[1] - limits[0])
    index = np.clip(np.round(np.nan_to_num(scaled) * 254.0), 0, 254).astype(np.uint8)
    index[~np.isfinite(values)] = _NO_VALUE
    table = colormaps[spec.cmap](np.linspace(0.0, 1.0, 255))[:, :3]
    table = np.vstack([table, _NO_VALUE_RGB])
    return CloudView(
        n_points=len(points),
        n_total=total,
        origin_m=tuple(float(v) for v in origin),
        extent_m=tuple(float(v) for v in extent),
        positions_b64=base64.b64encode(quantised.tobytes()).decode("ascii"),
        colours_b64=base64.b64encode(index.tobytes()).decode("ascii"),
        palette=np.round(table * 255).astype(int).tolist(),
        label=f"{spec.label}, {limits[0]:.3g} to {limits[1]:.3g}",
    )


def still_image(view: CloudView, title: str) -> bytes:
    """The fallback picture: the packed cloud seen from the camera (u right, v down),
    every point in its colour, as PNG bytes."""
    positions = np.frombuffer(base64.b64decode(view.positions_b64), dtype="<u2").reshape(-1, 3)
    points = positions / 65535.0 * np.asarray(view.extent_m) + np.asarray(view.origin_m)
    colours = (
        np.asarray(view.palette, dtype=np.float64)[
            np.frombuffer(base64.b64decode(view.colours_b64), dtype=np.uint8)
        ]
        / 255.0
    )
    figure = _figure()
    axes = figure.add_subplot()
    z = np.where(points[:, 2] > 0, points[:, 2], np.nan)
    axes.scatter(points[:, 0] / z, points[:, 1] / z, s=0.5, c=colours, linewidths=0)
    axes.invert_yaxis()
    axes.set_aspect("equal")
    axes.set_xlabel("x / z (camera frame)")
    axes.set_ylabel("y / z")
    axes.set_title(f"{title}\n{view.n_points:,} points; colour: {view.label}", fontsize=9)
    return png_bytes(figure)


#: The viewer: finds every ``.virtus-cloud`` block, reads its JSON payload, draws the points
#: with WebGL 1, or shows the block's still image when no WebGL context can be made.
VIEWER_JS = r"""
(function () {
  "use strict";
  function bytes(b64) {
    var text = atob(b64), out = new Uint8Array(text.length);
    for (var i = 0; i < text.length; i++) out[i] = text.charCodeAt(i);
    return out;
  }
  function perspective(fovy, aspect, near, far) {
    var f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1,
            0, 0, 2 * far * near * nf, 0];
  }
  function multiply(a, b) {
    var out = new Array(16);
    for (var c = 0; c < 4; c++) for (var r = 0; r < 4; r++) {
      var s = 0;
      for (var k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      out[c * 4 + r] = s;
    }
    return out;
  }
  function rotation(yaw, pitch) {
    var cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
    var ry = [cy, 0, -sy, 0, 0, 1, 0, 0, sy, 0, cy, 0, 0, 0, 0, 1];
    var rx = [1, 0, 0, 0, 0, cp, sp, 0, 0, -sp, cp, 0, 0, 0, 0, 1];
    return multiply(rx, ry);
  }
  function shader(gl, kind, source) {
    var s = gl.createShader(kind);
    gl.shaderSource(s, source);
    gl.compileShader(s);
    return s;
  }
  function attribute(gl, program, name, values, size, type) {
    // a normalised vertex attribute read from its own buffer of ``values``
    gl.bindBuffer(gl.ARRAY_BUFFER, gl.createBuffer());
    gl.bufferData(gl.ARRAY_BUFFER, values, gl.STATIC_DRAW);
    var location = gl.getAttribLocation(program, name);
    gl.enableVertexAttribArray(location);
    gl.vertexAttribPointer(location, size, type, true, 0, 0);
  }
  function showStill(block, canvas, still, mode) {
    canvas.style.display = "none";
    still.style.display = "block";
    block.setAttribute("data-mode", mode);
  }
  function start(block) {
    var canvas = block.querySelector("canvas");
    var still = block.querySelector(".virtus-still");
    var data = JSON.parse(block.querySelector("script.virtus-cloud-data").textContent);
    var gl = null;
    try {
      gl = canvas.getContext("webgl", {preserveDrawingBuffer: true, antialias: false});
    } catch (e) { gl = null; }
    if (!gl) {
      showStill(block, canvas, still, "still");
      return;
    }
    block.setAttribute("data-mode", "webgl");
    var vs = "attribute vec3 q; attribute float c; uniform mat4 m; uniform vec3 box;" +
      "uniform float size; varying float vc; void main() {" +
      "vec3 p = (q - 0.5) * box * 2.0; p.y = -p.y; p.z = -p.z;" +
      "gl_Position = m * vec4(p, 1.0); gl_PointSize = size; vc = c; }";
    var fs = "precision mediump float; varying float vc; uniform sampler2D lut;" +
      "void main() { gl_FragColor = texture2D(lut, vec2(vc * 255.0 / 256.0 + 0.5 / 256.0, 0.5)); }";
    var program = gl.createProgram();
    gl.attachShader(program, shader(gl, gl.VERTEX_SHADER, vs));
    gl.attachShader(program, shader(gl, gl.FRAGMENT_SHADER, fs));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) {
      showStill(block, canvas, still, "no-shader");
      return;
    }
    gl.useProgram(program);
    var positions = bytes(data.positions), colours = bytes(data.colours);
    attribute(gl, program, "q", positions, 3, gl.UNSIGNED_SHORT);
    attribute(gl, program, "c", colours, 1, gl.UNSIGNED_BYTE);
    var lut = new Uint8Array(256 * 4);
    for (var i = 0; i < 256; i++) {
      lut[4 * i] = data.palette[i][0]; lut[4 * i + 1] = data.palette[i][1];
      lut[4 * i + 2] = data.palette[i][2]; lut[4 * i + 3] = 255;
    }
    gl.bindTexture(gl.TEXTURE_2D, gl.createTexture());
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, 256, 1, 0, gl.RGBA, gl.UNSIGNED_BYTE, lut);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    var big = Math.max(data.extent[0], data.extent[1], data.extent[2]);
    var half = [data.extent[0] / big, data.extent[1] / big, data.extent[2] / big];
    gl.uniform3fv(gl.getUniformLocation(program, "box"), half.map(function (h) { return h / 2; }));
    gl.uniform1f(gl.getUniformLocation(program, "size"), 2.0);
    var where = gl.getUniformLocation(program, "m");
    var view = {yaw: 0, pitch: 0, distance: 2.2};
    function draw() {
      gl.viewport(0, 0, canvas.width, canvas.height);
      gl.clearColor(1, 1, 1, 1);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      gl.enable(gl.DEPTH_TEST);
      var move = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, -view.distance, 1];
      var m = multiply(perspective(0.8, canvas.width / canvas.height, 0.01, 100),
                       multiply(move, rotation(view.yaw, view.pitch)));
      gl.uniformMatrix4fv(where, false, new Float32Array(m));
      gl.drawArrays(gl.POINTS, 0, data.n);
    }
    var dragging = null;
    canvas.addEventListener("mousedown", function (e) { dragging = [e.clientX, e.clientY]; });
    window.addEventListener("mouseup", function () { dragging = null; });
    window.addEventListener("mousemove", function (e) {
      if (!dragging) return;
      view.yaw += (e.clientX - dragging[0]) * 0.01;
      view.pitch += (e.clientY - dragging[1]) * 0.01;
      dragging = [e.clientX, e.clientY];
      draw();
    });
    canvas.addEventListener("wheel", function (e) {
      e.preventDefault();
      view.distance = Math.min(20, Math.max(0.3, view.distance * Math.exp(e.deltaY * 0.001)));
      draw();
    }, {passive: false});
    canvas.addEventListener("dblclick", function () {
      view = {yaw: 0, pitch: 0, distance: 2.2};
      draw();
    });
    draw();
  }
  var blocks = document.querySelectorAll(".virtus-cloud");
  for (var b = 0; b < blocks.length; b++) start(blocks[b]);
})();
"""

"""OpenGL drawing of the 3-D view (PyOpenGL, core profile 3.3): a point program colouring by
height or by the camera's ambient gray in the shader, a line program, and vertex buffers that
upload only what changed (the colour toggle is a uniform: nothing is uploaded again). Every
method that draws needs the widget's GL context current."""

from __future__ import annotations

import ctypes

import numpy as np
from OpenGL import GL

from insitu.ui.model.cloud_lod import TiledCloud, draw_ranges
from insitu.ui.model.scene_data import COLORMAP_STOPS


def _cmap_glsl() -> str:
    s = COLORMAP_STOPS
    lines = ["vec3 cmap(float t) {"]
    for i in range(1, len(s)):
        a, b = s[i - 1], s[i]
        lines.append(f"  if (t <= {b[0]:.4f}) return mix(vec3({a[1]:.4f}, {a[2]:.4f}, "
                     f"{a[3]:.4f}), vec3({b[1]:.4f}, {b[2]:.4f}, {b[3]:.4f}), "
                     f"(t - {a[0]:.4f}) / {b[0] - a[0]:.4f});")
    lines.append(f"  return vec3({s[-1][1]:.4f}, {s[-1][2]:.4f}, {s[-1][3]:.4f});\n}}")
    return "\n".join(lines)


POINT_VS = f"""#version 330 core
layout(location = 0) in vec3 position;
layout(location = 1) in float ambient;
uniform mat4 mvp;
uniform vec2 z_range;
uniform vec2 ambient_range;
uniform int camera_colours;
uniform float point_size;
out vec3 colour;
{_cmap_glsl()}
void main() {{
  gl_Position = mvp * vec4(position, 1.0);
  gl_PointSize = point_size;
  if (camera_colours == 1)
    colour = vec3(clamp((ambient - ambient_range.x)
                        / max(ambient_range.y - ambient_range.x, 1e-6), 0.0, 1.0));
  else
    colour = cmap(clamp((position.z - z_range.x) / max(z_range.y - z_range.x, 1e-6), 0.0, 1.0));
}}
"""
POINT_FS = """#version 330 core
in vec3 colour;
uniform float shade;
out vec4 frag;
void main() { frag = vec4(colour * shade, 1.0); }
"""
LINE_VS = """#version 330 core
layout(location = 0) in vec3 position;
uniform mat4 mvp;
void main() {
  gl_Position = mvp * vec4(position, 1.0);
  gl_Position.z -= 0.0005 * gl_Position.w;   // lines on the surface win over its points
}
"""
LINE_FS = """#version 330 core
uniform vec4 colour;
out vec4 frag;
void main() { frag = colour; }
"""


def _program(vs: str, fs: str) -> int:
    def shader(kind, src):
        sh = GL.glCreateShader(kind)
        GL.glShaderSource(sh, src)
        GL.glCompileShader(sh)
        if not GL.glGetShaderiv(sh, GL.GL_COMPILE_STATUS):
            raise RuntimeError(f"shader: {GL.glGetShaderInfoLog(sh).decode(errors='replace')}")
        return sh
    prog = GL.glCreateProgram()
    shaders = [shader(GL.GL_VERTEX_SHADER, vs), shader(GL.GL_FRAGMENT_SHADER, fs)]
    for sh in shaders:
        GL.glAttachShader(prog, sh)
    GL.glLinkProgram(prog)
    if not GL.glGetProgramiv(prog, GL.GL_LINK_STATUS):
        raise RuntimeError(f"program: {GL.glGetProgramInfoLog(prog).decode(errors='replace')}")
    for sh in shaders:
        GL.glDeleteShader(sh)
    return prog


class VertexBuffer:
    """(N, C) float32 values of one vertex attribute (C = 3: positions, 1: ambient gray) in
    a VBO. :meth:`set` replaces them, :meth:`append` adds to them; :meth:`sync` uploads only
    what changed (the new tail, or everything when the capacity must grow — doubled, so a
    growing cloud re-uploads O(log N) times); ``uploads`` counts the uploads."""

    def __init__(self, components: int = 3) -> None:
        self.components = components
        self.vbo = None
        self.capacity = 0
        self.uploaded = 0
        self.uploads = 0
        self.version = 0                # changes with every set or append
        self.data = np.zeros((0, components), np.float32)

    @property
    def count(self) -> int:
        return len(self.data)

    def set(self, values: np.ndarray) -> None:
        self.data = np.ascontiguousarray(values, np.float32).reshape(-1, self.components)
        self.uploaded = 0
        self.version += 1

    def append(self, values: np.ndarray) -> None:
        more = np.asarray(values, np.float32).reshape(-1, self.components)
        self.data = np.concatenate([self.data, more])
        self.version += 1

    def sync(self) -> None:
        if self.vbo is None:
            self.vbo = GL.glGenBuffers(1)
        if self.uploaded == self.count:
            return
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.vbo)
        size = 4 * self.components
        if self.count > self.capacity or self.uploaded == 0:
            grown = 2 * self.capacity if self.uploaded else 0     # a new set: its own size
            self.capacity = max(self.count, min(grown, 1 << 26), 1024)
            GL.glBufferData(GL.GL_ARRAY_BUFFER, self.capacity * size, None, GL.GL_DYNAMIC_DRAW)
            self.uploaded = 0
        tail = self.data[self.uploaded:]
        GL.glBufferSubData(GL.GL_ARRAY_BUFFER, self.uploaded * size, tail.nbytes, tail)
        self.uploaded = self.count
        self.uploads += 1

    def point_at(self, location: int, stride: int = 1) -> None:
        """Attribute ``location`` of the bound VAO reads every ``stride``-th value."""
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.vbo)
        GL.glEnableVertexAttribArray(location)
        GL.glVertexAttribPointer(location, self.components, GL.GL_FLOAT, GL.GL_FALSE,
                                 4 * self.components * stride, ctypes.c_void_p(0))

    def delete(self) -> None:
        if self.vbo is not None:
            GL.glDeleteBuffers(1, [self.vbo])
            self.vbo = None


class LineBuffer:
    """GL_LINES vertex pairs (2M, 3) mm in a VAO."""

    def __init__(self) -> None:
        self.vao = None
        self.positions = VertexBuffer(3)

    @property
    def count(self) -> int:
        return self.positions.count

    def set(self, vertices: np.ndarray) -> None:
        self.positions.set(vertices)

    def draw(self) -> None:
        if self.vao is None:
            self.vao = GL.glGenVertexArrays(1)
        self.positions.sync()
        if self.positions.count:
            GL.glBindVertexArray(self.vao)
            self.positions.point_at(0)
            GL.glDrawArrays(GL.GL_LINES, 0, self.positions.count)

    def delete(self) -> None:
        self.positions.delete()
        if self.vao is not None:
            GL.glDeleteVertexArrays(1, [self.vao])
            self.vao = None


INTERACTIVE_POINTS = 150_000    # drawn while the view moves, at most
REST_POINTS = 400_000           # drawn at rest, at most; fewer in the view: every one of them
POINTS_PER_PX = (0.3, 0.6)      # and at most this many per pixel of the view (moving, at rest):
                                # 2-px points cover a cloud that fills the view twice over


class PointLayer:
    """The cloud: positions (tiled in xy for culling, :class:`~insitu.ui.model.cloud_lod
    .TiledCloud`) and, when it has one, the ambient gray of each point. Each frame draws the
    tiles in the view, every k-th point of them so that at most ``budget`` are drawn (a
    strided attribute pointer: no second copy of the cloud, nothing uploaded again)."""

    def __init__(self) -> None:
        self.vao = None
        self.positions = VertexBuffer(3)
        self.ambient = VertexBuffer(1)
        self.tiles: TiledCloud | None = None
        self.drawn = 0                  # points drawn by the last frame
        self.stride = 1

    def set(self, points: np.ndarray, ambient: np.ndarray | None = None) -> None:
        self.tiles = TiledCloud.of(np.asarray(points, np.float64).reshape(-1, 3))
        self.positions.set(self.tiles.points)
        self.ambient.set(np.zeros(0) if ambient is None
                         else np.asarray(ambient, np.float32)[self.tiles.order])

    def append(self, points: np.ndarray) -> None:
        """Live growth: untiled (one range), no ambient gray."""
        self.tiles = None
        self.positions.append(points)
        self.ambient.set(np.zeros(0))

    @property
    def count(self) -> int:
        return self.positions.count

    @property
    def has_ambient(self) -> bool:
        return self.positions.count > 0 and self.ambient.count == self.positions.count

    def draw(self, mvp: np.ndarray, budget: int) -> None:
        if self.vao is None:
            self.vao = GL.glGenVertexArrays(1)
        self.positions.sync()
        self.ambient.sync()
        n = self.positions.count
        if self.tiles is not None:
            starts, ends = self.tiles.visible_runs(mvp)
        else:
            starts, ends = np.array([0]), np.array([n])
        k, first, count = draw_ranges(starts, ends, budget)
        self.stride, self.drawn = k, int(count.sum())
        if not self.drawn:
            return
        GL.glBindVertexArray(self.vao)
        self.positions.point_at(0, k)
        if self.has_ambient:
            self.ambient.point_at(1, k)
        else:
            GL.glDisableVertexAttribArray(1)
            GL.glVertexAttrib1f(1, 0.5)
        GL.glMultiDrawArrays(GL.GL_POINTS, first.astype(np.int32), count.astype(np.int32),
                             len(first))

    def delete(self) -> None:
        self.positions.delete()
        self.ambient.delete()
        if self.vao is not None:
            GL.glDeleteVertexArrays(1, [self.vao])
            self.vao = None


class Renderer:
    """The point cloud and named line layers, drawn with one matrix. Of the cloud's points in
    the view, a frame draws at most :meth:`budget` (evenly thinned, in scan order), so a
    software renderer keeps up; a view showing fewer gets every point.
    ``camera_colours``: the points take the ambient frame's gray (when the cloud has it)."""

    def __init__(self) -> None:
        self.points = PointLayer()
        self.z_range = (0.0, 1.0)
        self.ambient_range = (0.0, 1.0)
        self.camera_colours = False
        self.point_size = 2.0
        self.shade = 1.0                 # the cloud's colours × this (dimmed under pens' paths)
        self.lines: dict[str, tuple[LineBuffer, tuple[float, ...], bool]] = {}
        self._point_prog = self._line_prog = None

    def initialize(self) -> str:
        """Compile the programs; returns the GL renderer's name (e.g. "llvmpipe ...")."""
        self._point_prog = _program(POINT_VS, POINT_FS)
        self._line_prog = _program(LINE_VS, LINE_FS)
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glEnable(GL.GL_PROGRAM_POINT_SIZE)
        GL.glEnable(GL.GL_BLEND)
        # blend colours; keep the framebuffer opaque (a grab shows what the screen shows)
        GL.glBlendFuncSeparate(GL.GL_SRC_ALPHA, GL.GL_ONE_MINUS_SRC_ALPHA, GL.GL_ZERO, GL.GL_ONE)
        return (GL.glGetString(GL.GL_RENDERER) or b"?").decode()

    def set_lines(self, name: str, vertices: np.ndarray, colour, on_top: bool = False) -> None:
        """GL_LINES vertex pairs (2M, 3) mm of layer ``name`` in RGBA ``colour``; ``on_top``:
        drawn over everything (no depth test: the axes)."""
        buf = self.lines.get(name, (LineBuffer(),))[0]
        buf.set(vertices)
        self.lines[name] = (buf, tuple(colour), on_top)

    def budget(self, fast: bool, view_px: int) -> int:
        """Points a frame draws at most: moving (``fast``) or at rest, in a view of
        ``view_px`` pixels."""
        cap = INTERACTIVE_POINTS if fast else REST_POINTS
        return int(min(cap, POINTS_PER_PX[0 if fast else 1] * view_px))

    def draw(self, mvp: np.ndarray, fast: bool = False, view_px: int = 1 << 30,
             background=(0.11, 0.12, 0.14)) -> None:
        """Clear and draw everything; ``fast``: the view is moving; ``view_px``: its size,
        pixels (the budget of points follows both)."""
        GL.glClearColor(*background, 1.0)
        GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)
        m = np.ascontiguousarray(mvp.T, np.float32)
        prog = self._point_prog
        GL.glUseProgram(prog)
        GL.glUniformMatrix4fv(GL.glGetUniformLocation(prog, "mvp"), 1, GL.GL_FALSE, m)
        GL.glUniform2f(GL.glGetUniformLocation(prog, "z_range"), *self.z_range)
        GL.glUniform2f(GL.glGetUniformLocation(prog, "ambient_range"), *self.ambient_range)
        GL.glUniform1i(GL.glGetUniformLocation(prog, "camera_colours"),
                       int(self.camera_colours and self.points.has_ambient))
        GL.glUniform1f(GL.glGetUniformLocation(prog, "point_size"), self.point_size)
        GL.glUniform1f(GL.glGetUniformLocation(prog, "shade"), self.shade)
        self.points.draw(mvp, self.budget(fast, view_px))
        GL.glUseProgram(self._line_prog)
        GL.glUniformMatrix4fv(GL.glGetUniformLocation(self._line_prog, "mvp"), 1, GL.GL_FALSE, m)
        loc = GL.glGetUniformLocation(self._line_prog, "colour")
        for top in (False, True):
            if top:
                GL.glDisable(GL.GL_DEPTH_TEST)
            for buf, colour, on_top in self.lines.values():
                if on_top == top:
                    GL.glUniform4f(loc, *colour)
                    buf.draw()
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glBindVertexArray(0)
        GL.glUseProgram(0)

    def delete(self) -> None:
        self.points.delete()
        for buf, *_ in self.lines.values():
            buf.delete()

"""OpenGL drawing of the 3-D view (PyOpenGL, core profile 3.3): a point program colouring by
height in the shader, a line program, and vertex buffers that upload only what changed.
Every method needs the widget's GL context current."""

from __future__ import annotations

import ctypes

import numpy as np
from OpenGL import GL

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
uniform mat4 mvp;
uniform vec2 z_range;
uniform float point_size;
out vec3 colour;
{_cmap_glsl()}
void main() {{
  gl_Position = mvp * vec4(position, 1.0);
  gl_PointSize = point_size;
  colour = cmap(clamp((position.z - z_range.x) / max(z_range.y - z_range.x, 1e-6), 0.0, 1.0));
}}
"""
POINT_FS = """#version 330 core
in vec3 colour;
out vec4 frag;
void main() { frag = vec4(colour, 1.0); }
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
    """(N, 3) float32 positions in a VAO + VBO. :meth:`set` replaces them, :meth:`append`
    adds to them; :meth:`sync` uploads only what changed (the new tail, or everything when
    the capacity must grow — doubled, so a growing cloud re-uploads O(log N) times)."""

    def __init__(self) -> None:
        self.vao = self.vbo = None
        self.capacity = 0
        self.uploaded = 0
        self.version = 0                # changes with every set or append
        self.data = np.zeros((0, 3), np.float32)

    @property
    def count(self) -> int:
        return len(self.data)

    def set(self, points: np.ndarray) -> None:
        self.data = np.ascontiguousarray(points, np.float32).reshape(-1, 3)
        self.uploaded = 0
        self.version += 1

    def append(self, points: np.ndarray) -> None:
        self.data = np.concatenate([self.data, np.asarray(points, np.float32).reshape(-1, 3)])
        self.version += 1

    def sync(self) -> None:
        if self.vao is None:
            self.vao, self.vbo = GL.glGenVertexArrays(1), GL.glGenBuffers(1)
            GL.glBindVertexArray(self.vao)
            GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.vbo)
            GL.glEnableVertexAttribArray(0)
            GL.glVertexAttribPointer(0, 3, GL.GL_FLOAT, GL.GL_FALSE, 12, ctypes.c_void_p(0))
            GL.glBindVertexArray(0)
        if self.uploaded == self.count:
            return
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self.vbo)
        if self.count > self.capacity or self.uploaded == 0:
            self.capacity = max(self.count, min(2 * self.capacity, 1 << 26), 1024)
            GL.glBufferData(GL.GL_ARRAY_BUFFER, self.capacity * 12, None, GL.GL_DYNAMIC_DRAW)
            self.uploaded = 0
        tail = self.data[self.uploaded:]
        GL.glBufferSubData(GL.GL_ARRAY_BUFFER, self.uploaded * 12, tail.nbytes, tail)
        self.uploaded = self.count

    def draw(self, mode) -> None:
        if self.count:
            GL.glBindVertexArray(self.vao)
            GL.glDrawArrays(mode, 0, self.count)

    def delete(self) -> None:
        if self.vao is not None:
            GL.glDeleteBuffers(1, [self.vbo])
            GL.glDeleteVertexArrays(1, [self.vao])
            self.vao = self.vbo = None


INTERACTIVE_POINTS = 150_000


class Renderer:
    """The point cloud and named line layers, drawn with one matrix. While the operator
    moves the view (``fast``), a cloud of more than :data:`INTERACTIVE_POINTS` is drawn from
    an evenly thinned copy (``preview``: every k-th point, in scan order), so a software
    renderer keeps up; at rest every point is drawn."""

    def __init__(self) -> None:
        self.points = VertexBuffer()
        self.preview = VertexBuffer()
        self._preview_of = -1
        self.z_range = (0.0, 1.0)
        self.point_size = 2.0
        self.lines: dict[str, tuple[VertexBuffer, tuple[float, float, float, float]]] = {}
        self._point_prog = self._line_prog = None

    def initialize(self) -> str:
        """Compile the programs; returns the GL renderer's name (e.g. "llvmpipe ...")."""
        self._point_prog = _program(POINT_VS, POINT_FS)
        self._line_prog = _program(LINE_VS, LINE_FS)
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glEnable(GL.GL_PROGRAM_POINT_SIZE)
        GL.glEnable(GL.GL_BLEND)
        GL.glBlendFunc(GL.GL_SRC_ALPHA, GL.GL_ONE_MINUS_SRC_ALPHA)
        return (GL.glGetString(GL.GL_RENDERER) or b"?").decode()

    def set_lines(self, name: str, vertices: np.ndarray, colour) -> None:
        """GL_LINES vertex pairs (2M, 3) mm of layer ``name`` in RGBA ``colour``."""
        buf = self.lines.get(name, (VertexBuffer(), colour))[0]
        buf.set(vertices)
        self.lines[name] = (buf, tuple(colour))

    def _cloud(self, fast: bool) -> VertexBuffer:
        n = self.points.count
        if not fast or n <= INTERACTIVE_POINTS:
            return self.points
        if self._preview_of != self.points.version:
            self.preview.set(self.points.data[::-(-n // INTERACTIVE_POINTS)])
            self._preview_of = self.points.version
        return self.preview

    def draw(self, mvp: np.ndarray, fast: bool = False, background=(0.11, 0.12, 0.14)) -> None:
        """Clear and draw everything; ``fast``: the thinned cloud (the view is moving)."""
        GL.glClearColor(*background, 1.0)
        GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)
        m = np.ascontiguousarray(mvp.T, np.float32)
        cloud = self._cloud(fast)
        cloud.sync()
        if cloud.count:
            GL.glUseProgram(self._point_prog)
            GL.glUniformMatrix4fv(GL.glGetUniformLocation(self._point_prog, "mvp"), 1,
                                  GL.GL_FALSE, m)
            GL.glUniform2f(GL.glGetUniformLocation(self._point_prog, "z_range"), *self.z_range)
            GL.glUniform1f(GL.glGetUniformLocation(self._point_prog, "point_size"),
                           self.point_size)
            cloud.draw(GL.GL_POINTS)
        GL.glUseProgram(self._line_prog)
        GL.glUniformMatrix4fv(GL.glGetUniformLocation(self._line_prog, "mvp"), 1, GL.GL_FALSE, m)
        loc = GL.glGetUniformLocation(self._line_prog, "colour")
        for buf, colour in self.lines.values():
            buf.sync()
            GL.glUniform4f(loc, *colour)
            buf.draw(GL.GL_LINES)
        GL.glBindVertexArray(0)
        GL.glUseProgram(0)

    def delete(self) -> None:
        self.points.delete()
        self.preview.delete()
        for buf, _ in self.lines.values():
            buf.delete()

"""The GL backend: the paper's cones and pyramids in a z-buffer (§3.2, Table 1, after
Hoff et al. 1999), rendered headless with moderngl on EGL (Mesa's llvmpipe without a
GPU, the GPU's driver where there is one).

How one iteration runs
----------------------
1. **Cone heights (host).**  A cone drawn too small leaves pixels that no site claims
   (measured: a fixed 1/√N radius left 52 000 pixels unlabelled), so every call bounds
   them from the actual sites.  The raster is cut into ``block`` x ``block`` tiles; for
   each tile containing region pixels, ``UB = min_j max_corners d_j`` over a few candidate
   sites j (picked by a distance transform of the occupied tiles) is an upper bound on
   the nearest-site distance of every pixel of the tile (d_j is convex, so its maximum
   over the tile's box is at a corner).  A pixel
   x in the cell of site i has ``d_i(x) <= UB(tile(x))`` and so lies within
   ``r_i·circumradius·s_i`` pixels of p_i; site i's cone height r_i is the largest UB over
   the tiles that close to it (a max filter over the tile grid, sampled at the site).  So
   every pixel of cell i has ``d_i <= r_i``: inside cone i's footprint.  The moments shader
   counts region pixels that no cone reached; any such pixel raises RuntimeError (a bug,
   never a silent -1).
2. **Draw (one instanced call).**  Each site is the fan of triangles over its unit ball
   from :mod:`cvt.metrics`, rotated by θ_i, scaled by ``s_i·r_i`` and raised to height r_i:
   ``cone`` mode lets the rasteriser interpolate the depth (the pyramid over a K-gon ball
   has K faces, each one linear facet of the gauge, so it is exact for any convex
   polygon); ``exact`` mode evaluates d_i(x) per fragment from
   :func:`cvt.metrics.compile_sites` (the max over a polygon's K facets, or the quadratic
   form) and writes ``gl_FragDepth``.  A polygon's (N, K, 2) facets go to a storage
   buffer, in the order of the pyramid's faces; the vertex stage hands each site's K
   facets to its fragments as flat varyings, or, where K exceeds what the varyings hold,
   the facets of the face drawn and of its two neighbours (exact up to the rasteriser's
   rounding at the faces' shared edges; see the fragment shader).  The depth attachment
   is 32-bit float (moderngl's own is 24-bit; see :func:`_depth32f_texture`) and holds
   linear distance times a power of two,
   so float order is kept exactly.  Depth test LESS with instances drawn in index order
   keeps the first drawn on equal depth: ties go to the lower index.  The colour
   attachment is R32UI holding id + 1, cleared to 0 (clearing an integer attachment in
   moderngl writes float bit patterns; 0.0 is 0).
3. **Moments (compute shader).**  One invocation per 64-pixel run of a row accumulates
   runs of equal labels and adds them with atomics into an SSBO of per-site sums (count
   and 64-bit Σj, Σi, Σj², Σi² as lo/hi words with carry); only N·9 words come back.  The
   label raster is read back only by :meth:`GLBackend.label`.

Curved cones (l2, l2-axial): the ellipse is replaced by its circumscribed M-gon (the
affine image of a circumscribed regular M-gon, so it contains the ball) and the pyramid's
height is scaled by ``2/(1+cos(π/M))``; the height is then within a relative
``δ = tan²(π/2M)`` of the exact distance, i.e. it is the exact distance of a point on the
same ray from the site at most ``δ·ρ`` pixels away, ρ the footprint's radius in pixels.
M is chosen per call as the smallest of a fixed ladder with ``δ·ρ_max <= max_error_px``
(default 0.1 px).

One GL context serves the whole process (:func:`shared_context`): with several moderngl
contexts calls go to the last one made current, and switching on every call doubled the
time (measured on llvmpipe).
"""

from __future__ import annotations

import ctypes
import math

import numpy as np
from scipy.ndimage import distance_transform_edt, maximum_filter

from compact_distributions.cvt.errors import BackendUnavailable, InputError
from compact_distributions.cvt.metrics import Metric, compile_sites
from compact_distributions.cvt.moments import Moments
from compact_distributions.cvt.problem import Grid
from compact_distributions.cvt.validate import one_of, real_number, whole_number

from .base import Backend

MODES = ("cone", "exact")
# Segment counts tried for curved cones, smallest first.
ELLIPSE_SEGMENTS = (8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512)
# The footprint polygon of an elliptic ball in exact mode only has to contain the ball.
EXACT_FOOTPRINT_SEGMENTS = 8
RUN_LENGTH = 64  # pixels of a row per moments-shader invocation
SUM_WORDS = 9  # count, then lo/hi words of Σj, Σi, Σj², Σi²

_GL_TEXTURE_2D = 0x0DE1
_GL_DEPTH_COMPONENT = 0x1902
_GL_DEPTH_COMPONENT32F = 0x8CAC
_GL_FLOAT = 0x1406
_GL_TEXTURE_INTERNAL_FORMAT = 0x1003

# ---------------------------------------------------------------------------- context
_CONTEXT = None
_CONTEXT_ERROR: str | None = None
_RAW_GL = None


def shared_context():
    """The process's one headless GL context, created on first use and then reused.

    Raises BackendUnavailable with one line naming what is missing: moderngl, EGL or a
    driver with OpenGL 4.3 (compute shaders and storage buffers)."""
    global _CONTEXT, _CONTEXT_ERROR
    if _CONTEXT is not None:
        return _CONTEXT
    if _CONTEXT_ERROR is not None:  # do not retry a slow failure on every probe
        raise BackendUnavailable(_CONTEXT_ERROR)
    try:
        import moderngl
    except ImportError:
        _CONTEXT_ERROR = "gl backend: moderngl is not installed (pip install 'compact-distributions[gl]')"
        raise BackendUnavailable(_CONTEXT_ERROR) from None
    try:
        # ask for 4.3: moderngl asks EGL for 3.3 by default, and NVIDIA's driver then gives
        # exactly 3.3 (Mesa gives its highest whatever is asked)
        ctx = moderngl.create_context(standalone=True, backend="egl", require=430)
    except Exception as exc:  # moderngl raises plain Exception for EGL failures
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        _CONTEXT_ERROR = f"gl backend: no headless EGL OpenGL context ({reason})"
        raise BackendUnavailable(_CONTEXT_ERROR) from None
    if ctx.version_code < 430:
        _CONTEXT_ERROR = (
            f"gl backend: needs OpenGL 4.3 (compute shaders), the driver gives "
            f"{ctx.info.get('GL_VERSION', ctx.version_code)}"
        )
        ctx.release()
        raise BackendUnavailable(_CONTEXT_ERROR)
    _CONTEXT = ctx
    return ctx


class _RawGL:
    """The three GL entry points moderngl does not expose, looked up through EGL."""

    def __init__(self):
        egl = ctypes.CDLL("libEGL.so.1")
        egl.eglGetProcAddress.restype = ctypes.c_void_p
        egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]

        def fn(name, *args):
            addr = egl.eglGetProcAddress(name.encode())
            if not addr:
                raise OSError(f"{name} not found")
            return ctypes.CFUNCTYPE(None, *args)(addr)

        u, i = ctypes.c_uint, ctypes.c_int
        self.bind_texture = fn("glBindTexture", u, u)
        self.tex_image_2d = fn("glTexImage2D", u, i, i, i, i, i, u, u, ctypes.c_void_p)
        self.get_tex_level_parameteriv = fn("glGetTexLevelParameteriv", u, i, u, ctypes.POINTER(i))


def _depth32f_texture(ctx, size):
    """A depth texture with a 32-bit float store.

    moderngl only makes DEPTH_COMPONENT24 ones, where nearby distances collapse
    (measured: hundreds of wrong pixels at N = 4000); its texture is re-specified in place as
    DEPTH_COMPONENT32F, so moderngl still knows it as a depth attachment."""
    global _RAW_GL
    tex = ctx.depth_texture(size)
    try:
        if _RAW_GL is None:
            _RAW_GL = _RawGL()
        gl = _RAW_GL
        gl.bind_texture(_GL_TEXTURE_2D, tex.glo)
        gl.tex_image_2d(
            _GL_TEXTURE_2D,
            0,
            _GL_DEPTH_COMPONENT32F,
            size[0],
            size[1],
            0,
            _GL_DEPTH_COMPONENT,
            _GL_FLOAT,
            None,
        )
        fmt = ctypes.c_int(0)
        gl.get_tex_level_parameteriv(_GL_TEXTURE_2D, 0, _GL_TEXTURE_INTERNAL_FORMAT, ctypes.byref(fmt))
        gl.bind_texture(_GL_TEXTURE_2D, 0)
    except OSError as exc:
        tex.release()
        raise BackendUnavailable(
            f"gl backend: cannot reach the GL library for a float depth buffer ({exc})"
        ) from None
    if fmt.value != _GL_DEPTH_COMPONENT32F:
        tex.release()
        raise BackendUnavailable("gl backend: the driver gives no 32-bit float depth buffer")
    return tex


# ---------------------------------------------------------------------------- shaders
_VERTEX_SHADER = """
#version 430
in vec3 in_vert;      // unit-ball frame: x, y, height (the gauge this vertex stands for)
in vec2 in_site;      // p_i, pixels
in vec2 in_rot;       // cos θ_i, sin θ_i
in vec2 in_size;      // s_i·r_i (pixels per unit of the ball), r_i·depth_scale
in vec4 in_c0;        // exact mode, ellipses: the quadratic form (qxx, qxy, qyy, -)
uniform vec2 u_raster;
flat out uint v_id;
flat out vec2 v_site;
flat out vec4 v_c0;
#if defined(FACET_VARYINGS) || defined(FACE_FACETS)
// exact mode, polygons: the K facets of each site, site-major, in the order of the faces
layout(std430, binding = 2) readonly buffer Facets { vec2 facets[]; };
#endif
#if defined(FACET_VARYINGS)
// all K facets, two to a vec4 (an odd K repeats facet 0, which leaves the max unchanged)
flat out vec4 v_f[(FACETS + 1) / 2];
#elif defined(FACE_FACETS)
// the facet of this face (three vertices per face) and those of the faces either side
flat out vec4 v_f[2];
#endif
void main() {
    vec2 r = in_vert.xy * in_size.x;
    vec2 pos = in_site + vec2(in_rot.x * r.x - in_rot.y * r.y, in_rot.y * r.x + in_rot.x * r.y);
    float depth = in_vert.z * in_size.y;                 // linear distance, scaled into [0, 1)
    gl_Position = vec4(pos / u_raster * 2.0 - 1.0, depth * 2.0 - 1.0, 1.0);
    v_id = uint(gl_InstanceID) + 1u;                     // 0 is "no site"
    v_site = in_site;
    v_c0 = in_c0;
#if defined(FACET_VARYINGS)
    int base = gl_InstanceID * FACETS;
    for (int k = 0; k < (FACETS + 1) / 2; ++k) {
        int second = 2 * k + 1 < FACETS ? 2 * k + 1 : 0;
        v_f[k] = vec4(facets[base + 2 * k], facets[base + second]);
    }
#elif defined(FACE_FACETS)
    int base = gl_InstanceID * FACETS;
    int face = gl_VertexID / 3;
    vec2 own = facets[base + face];
    v_f[0] = vec4(facets[base + (face + FACETS - 1) % FACETS], own);
    v_f[1] = vec4(facets[base + (face + 1) % FACETS], own);
#endif
}
"""

_CONE_FRAGMENT_SHADER = """
#version 430
flat in uint v_id;
flat in vec2 v_site;
flat in vec4 v_c0;
layout(location = 0) out uint out_id;
void main() { out_id = v_id; }
"""

# d_i(x) per fragment.  ELLIPSE: the quadratic form; FACET_VARYINGS: max over the K
# facets from flat varyings; FACE_FACETS (more facets than the varyings hold): max over
# the facet of the pyramid face drawn and those of its two neighbours.  Inside face k's
# wedge the gauge is facet k exactly; a pixel centre that float32 geometry puts in a face
# not its own lies within the rounding ε of that face, so the facets left out exceed the
# max by at most 2·|f|·ε, a float tie.  (Reading all K facets per fragment from the
# buffer instead cost several times the whole draw.)
_EXACT_FRAGMENT_SHADER = """
#version 430
flat in uint v_id;
flat in vec2 v_site;
flat in vec4 v_c0;
uniform float u_depth_scale;
#if defined(FACET_VARYINGS)
flat in vec4 v_f[(FACETS + 1) / 2];
#elif defined(FACE_FACETS)
flat in vec4 v_f[2];
#endif
layout(location = 0) out uint out_id;
void main() {
    vec2 v = gl_FragCoord.xy - v_site;                   // pixel centre (j + 0.5, i + 0.5)
#if defined(ELLIPSE)
    float d = sqrt(max(v_c0.x * v.x * v.x + 2.0 * v_c0.y * v.x * v.y + v_c0.z * v.y * v.y, 0.0));
#elif defined(FACET_VARYINGS)
    float d = max(dot(v_f[0].xy, v), dot(v_f[0].zw, v));
    for (int k = 1; k < (FACETS + 1) / 2; ++k) d = max(d, max(dot(v_f[k].xy, v), dot(v_f[k].zw, v)));
#else
    float d = max(max(dot(v_f[0].xy, v), dot(v_f[0].zw, v)), dot(v_f[1].xy, v));
#endif
    gl_FragDepth = d * u_depth_scale;
    out_id = v_id;
}
"""

_MOMENTS_SHADER = """
#version 430
layout(local_size_x = 8, local_size_y = 8) in;
uniform usampler2D u_ids;     // id + 1, 0 where no cone reached
uniform usampler2D u_mask;    // 1 inside the region
uniform bool u_has_mask;
uniform ivec2 u_raster;
uniform int u_run;
layout(std430, binding = 0) buffer Sums { uint sums[]; };
layout(std430, binding = 1) buffer Missing { uint missing; };

void add64(uint slot, uint lo, uint hi) {
    if (lo == 0u && hi == 0u) return;
    uint old = atomicAdd(sums[slot], lo);
    uint carry;
    uaddCarry(old, lo, carry);
    hi += carry;
    if (hi != 0u) atomicAdd(sums[slot + 1u], hi);
}

void flush(uint id, uint row, uint n, uint sj, uint sjj_lo, uint sjj_hi) {
    uint base = (id - 1u) * 9u;
    atomicAdd(sums[base], n);
    add64(base + 1u, sj, 0u);
    add64(base + 3u, n * row, 0u);
    add64(base + 5u, sjj_lo, sjj_hi);
    uint hi, lo;
    umulExtended(n, row * row, hi, lo);
    add64(base + 7u, lo, hi);
}

void main() {
    int row = int(gl_GlobalInvocationID.y);
    int j0 = int(gl_GlobalInvocationID.x) * u_run;
    if (row >= u_raster.y || j0 >= u_raster.x) return;
    int j1 = min(j0 + u_run, u_raster.x);
    uint cur = 0u, n = 0u, sj = 0u, lo = 0u, hi = 0u, miss = 0u;
    for (int j = j0; j < j1; ++j) {
        uint id = texelFetch(u_ids, ivec2(j, row), 0).r;
        if (u_has_mask && texelFetch(u_mask, ivec2(j, row), 0).r == 0u) {
            id = 0u;
        } else if (id == 0u) {
            miss += 1u;
        }
        if (id != cur) {
            if (cur != 0u) flush(cur, uint(row), n, sj, lo, hi);
            cur = id; n = 0u; sj = 0u; lo = 0u; hi = 0u;
        }
        if (cur != 0u) {
            uint c;
            n += 1u;
            sj += uint(j);
            lo = uaddCarry(lo, uint(j) * uint(j), c);
            hi += c;
        }
    }
    if (cur != 0u) flush(cur, uint(row), n, sj, lo, hi);
    if (miss != 0u) atomicAdd(missing, miss);
}
"""


# ---------------------------------------------------------------------------- geometry
def ellipse_height_error(segments: int) -> float:
    """Relative error δ of the height of a curved cone drawn with ``segments`` sides."""
    return math.tan(math.pi / (2 * segments)) ** 2


def ellipse_segments(radius_px: float, max_error_px: float) -> int:
    """Fewest sides (from the ladder) whose height error δ·ρ stays within max_error_px."""
    for m in ELLIPSE_SEGMENTS:
        if ellipse_height_error(m) * radius_px <= max_error_px:
            return m
    return ELLIPSE_SEGMENTS[-1]


def cone_vertices(metric: Metric, segments: int) -> tuple[np.ndarray, float]:
    """Triangle list (3M, 3) of the unit cone of ``metric`` (x, y, height), and the
    factor by which its footprint exceeds the unit ball in the worst direction.

    Polygonal balls: the outline's vertices at height 1, exact.  Elliptic balls: the
    circumscribed M-gon (contains the ball), heights scaled by 2/(1+cos(π/M)) so the
    relative error is ±tan²(π/2M) instead of 0..1-cos(π/M)."""
    if metric.curved:
        c = math.cos(math.pi / segments)
        ring = metric.outline(segments) / c
        height = 2.0 / (1.0 + c)
        reach = 1.0 / c
    else:
        ring = metric.outline()
        height = 1.0
        reach = 1.0
    nxt = np.roll(ring, -1, axis=0)
    tris = np.zeros((len(ring), 3, 3), dtype=np.float32)
    tris[:, 1, :2], tris[:, 1, 2] = ring, height
    tris[:, 2, :2], tris[:, 2, 2] = nxt, height
    return tris.reshape(-1, 3), reach


def face_facets(metric: Metric) -> np.ndarray:
    """(K,) for a polygonal ball: the facet on which face k of :func:`cone_vertices` lies
    (the one whose gauge term is largest at the middle of the face's outer edge)."""
    ring = metric.outline()
    middle = (ring + np.roll(ring, -1, axis=0)) / 2
    return np.argmax(middle @ metric.normals.T / metric.offsets, axis=1)


class _Blocks:
    """Square tiles of the raster (``size`` pixels a side), which of them hold region
    pixels, the box of pixel centres of each, and a finer grid (``size // sub``) whose
    cells pick the candidate sites of a tile."""

    def __init__(self, grid: Grid, size: int, sub: int = 1):
        w, h = grid.width, grid.height
        if size % sub:
            sub = 1
        nbx, nby = -(-w // size), -(-h // size)
        if grid.mask is not None:
            padded = np.zeros((nby * size, nbx * size), dtype=bool)
            padded[:h, :w] = grid.mask
            self.active = padded.reshape(nby, size, nbx, size).any(axis=(1, 3)).ravel()
        else:
            self.active = np.ones(nby * nbx, dtype=bool)
        by, bx = np.divmod(np.arange(nby * nbx), nbx)
        self.x0, self.y0 = bx * size + 0.5, by * size + 0.5
        self.x1 = np.minimum((bx + 1) * size, w) - 0.5
        self.y1 = np.minimum((by + 1) * size, h) - 0.5
        self.size, self.sub, self.shape = size, sub, (nby, nbx)
        self.fine = size // sub
        self.fine_shape = (-(-h // self.fine), -(-w // self.fine))


def box_max_distance(coeffs, idx: np.ndarray, blocks: _Blocks) -> np.ndarray:
    """max of d_idx over each tile's box of pixel centres: d is convex, so the maximum is
    at a corner; for a polygonal ball each facet's maximum is taken separately."""
    px, py = coeffs.sites[idx, 0], coeffs.sites[idx, 1]
    vx0, vx1 = blocks.x0 - px, blocks.x1 - px
    vy0, vy1 = blocks.y0 - py, blocks.y1 - py
    if coeffs.curved:
        q = coeffs.quad[idx]
        out = None
        for vx in (vx0, vx1):
            for vy in (vy0, vy1):
                d2 = q[:, 0] * vx * vx + 2 * q[:, 1] * vx * vy + q[:, 2] * vy * vy
                out = d2 if out is None else np.maximum(out, d2)
        return np.sqrt(out)
    f = coeffs.facets[idx]
    out = None
    for k in range(f.shape[1]):
        fx, fy = f[:, k, 0], f[:, k, 1]
        d = np.maximum(fx * vx0, fx * vx1) + np.maximum(fy * vy0, fy * vy1)
        out = d if out is None else np.maximum(out, d)
    return out


def cone_heights(
    coeffs,
    scales: np.ndarray,
    metric: Metric,
    blocks: _Blocks,
    passes: int = 2,
    neighbours: bool | None = None,
) -> np.ndarray:
    """r_i: an upper bound on d_i over every region pixel whose nearest site is i.

    1. Candidates: each cell of the fine grid takes a site binned in its nearest occupied
       cell (Euclidean distance transform); a tile's candidates are those of its
       ``sub``² fine cells (and, for elongated balls, those of the 8 adjacent tiles).
       Any site is an upper bound on the nearest distance, so
       ``UB(tile) = min over candidates of max over the tile of d_j`` bounds every pixel
       of the tile.
    2. A pixel x of cell i has d_i(x) <= UB(tile(x)) and, with a valid r_i, lies within
       ``r_i·circumradius·s_i`` pixels of p_i; so the largest UB over the tiles that
       close to p_i's tile is again a valid r_i, no larger.  Start from the global max
       and repeat ``passes`` times (a max filter per distinct window size)."""
    sites = coeffs.sites
    n = len(sites)
    if neighbours is None:  # elongated balls (triangle, axial): worth ~40 % less fill
        neighbours = metric.circumradius > 1.5 * metric.inradius
    nsy, nsx = blocks.fine_shape
    occupied = np.full((nsy, nsx), -1, dtype=np.int64)
    fi = np.clip(np.floor(sites[:, 1] / blocks.fine).astype(np.int64), 0, nsy - 1)
    fj = np.clip(np.floor(sites[:, 0] / blocks.fine).astype(np.int64), 0, nsx - 1)
    occupied[fi, fj] = np.arange(n)
    if (occupied < 0).any():
        _, (ii, jj) = distance_transform_edt(occupied < 0, return_indices=True)
        occupied = occupied[ii, jj]
    nby, nbx = blocks.shape
    sub = blocks.sub
    occupied = np.pad(occupied, ((0, nby * sub - nsy), (0, nbx * sub - nsx)), mode="edge")
    cand = occupied.reshape(nby, sub, nbx, sub).transpose(0, 2, 1, 3).reshape(nby * nbx, sub * sub)
    if neighbours:  # the candidates of the 8 adjacent tiles too: for elongated balls the
        # Euclidean-nearest site is often far in the metric
        grid3 = np.pad(cand.reshape(nby, nbx, -1), ((1, 1), (1, 1), (0, 0)), mode="edge")
        cand = np.concatenate(
            [
                grid3[1 + dy : 1 + dy + nby, 1 + dx : 1 + dx + nbx].reshape(nby * nbx, -1)
                for dy in (-1, 0, 1)
                for dx in (-1, 0, 1)
            ],
            axis=1,
        )
    bound = box_max_distance(coeffs, cand[:, 0], blocks)
    for c in range(1, cand.shape[1]):
        np.minimum(bound, box_max_distance(coeffs, cand[:, c], blocks), out=bound)
    bound[~blocks.active] = 0.0
    tiles = bound.reshape(nby, nbx)

    radius = np.full(n, float(bound.max()))
    bi = np.clip(np.floor(sites[:, 1] / blocks.size).astype(np.int64), 0, nby - 1)
    bj = np.clip(np.floor(sites[:, 0] / blocks.size).astype(np.int64), 0, nbx - 1)
    px_per_unit = metric.circumradius * scales
    for _ in range(passes):
        half = np.ceil(radius * px_per_unit / blocks.size).astype(np.int64) + 1
        for h in np.unique(half):
            if 2 * h + 1 >= max(nby, nbx):
                continue  # the window spans the raster: the global bound stands
            sel = half == h
            local = maximum_filter(tiles, size=2 * h + 1, mode="constant", cval=0.0)
            np.minimum(radius, np.where(sel, local[bi, bj], np.inf), out=radius)
    return radius


# ---------------------------------------------------------------------------- backend
class GLBackend(Backend):
    """Labels and moments by rendering cones (``mode="cone"``, the paper's method) or
    per-fragment exact distances (``mode="exact"``) into a depth-tested id buffer."""

    name = "gl"
    bytes_per_pixel = (
        32  # the framebuffer is on the device; per site the instance data and the cone heights' bookkeeping
    )
    bytes_per_site = 8000

    def supports(self, metric, angles, scales) -> str | None:
        """Any convex polygon in both modes; exact mode reads a polygon's facets in the
        vertex stage, which OpenGL 4.3 lets a driver refuse (none of Mesa's or the GPU
        vendors' do)."""
        if (
            self.mode == "exact"
            and not metric.curved
            and self.ctx.info.get("GL_MAX_VERTEX_SHADER_STORAGE_BLOCKS", 0) < 1
        ):
            return "exact mode needs storage buffers in the vertex stage, which this GL driver lacks (use cone mode)"
        return super().supports(metric, angles, scales)

    def __init__(self, mode: str = "cone", max_error_px: float = 0.1, block: int = 8):
        self.mode = one_of(mode, "gl mode", MODES)
        self.max_error_px = real_number(max_error_px, "max_error_px", above=0.0)
        self.block = whole_number(block, "block", minimum=1)
        self.ctx = shared_context()
        self._programs: dict = {}
        self._geometry: dict = {}
        self._target = None  # (width, height, colour, depth, fbo)
        self._mask = None  # (mask copy or None, texture or None)
        self._blocks = None  # (grid key, _Blocks)
        self._instances = None
        self._facets = None  # exact mode, polygons: the (N, K, 2) facets as a storage buffer
        self._sums = None
        self._missing = None
        self._moments_program = None
        self.last_segments = None  # sides of the last curved cone drawn (for reports)
        self.last_heights = None  # r_i of the last call (for tests)

    # ------------------------------------------------------------------ interface
    def device(self) -> str:
        info = self.ctx.info
        return f"{info['GL_RENDERER']}, OpenGL {info['GL_VERSION']} ({self.mode} mode)"

    @property
    def variant(self) -> str:
        return f"gl-{self.mode}"

    def _label(self, sites, angles, scales, metric: Metric, grid: Grid) -> np.ndarray:
        self._render(sites, angles, scales, metric, grid)
        w, h = grid.width, grid.height
        raw = np.frombuffer(self._target[2].read(alignment=1), dtype=np.uint32).reshape(h, w)
        labels = raw.astype(np.int32) - 1
        if grid.mask is not None:
            labels[~grid.mask] = -1
        missing = int((labels == -1).sum() - (0 if grid.mask is None else (~grid.mask).sum()))
        self._check_covered(missing)
        return labels

    def _moments(self, sites, angles, scales, metric: Metric, grid: Grid) -> Moments:
        n = self._render(sites, angles, scales, metric, grid)
        ctx = self.ctx
        prog = self._sums_program()
        nbytes = n * SUM_WORDS * 4
        if self._sums is None or self._sums.size < nbytes:
            if self._sums is not None:
                self._sums.release()
            self._sums = ctx.buffer(reserve=nbytes)
            self._missing = self._missing or ctx.buffer(reserve=4)
        self._sums.clear()
        self._missing.clear()
        self._sums.bind_to_storage_buffer(0)
        self._missing.bind_to_storage_buffer(1)
        w, h = grid.width, grid.height
        self._target[2].use(location=0)
        mask_tex = self._mask_texture(grid)
        if mask_tex is not None:
            mask_tex.use(location=1)
        prog["u_ids"] = 0
        prog["u_mask"] = 1
        prog["u_has_mask"] = mask_tex is not None
        prog["u_raster"] = (w, h)
        prog["u_run"] = RUN_LENGTH
        ctx.memory_barrier()
        runs = -(-w // RUN_LENGTH)
        prog.run(-(-runs // 8), -(-h // 8), 1)
        ctx.memory_barrier()
        words = np.frombuffer(self._sums.read(size=nbytes), dtype=np.uint32).reshape(n, SUM_WORDS)
        self._check_covered(int(np.frombuffer(self._missing.read(), dtype=np.uint32)[0]))
        wide = words.astype(np.int64)

        def join(k):
            return wide[:, k] + (wide[:, k + 1] << 32)

        return Moments(wide[:, 0].copy(), join(1), join(3), join(5), join(7))

    def close(self) -> None:
        """Release this backend's buffers and targets; the shared context stays."""
        for obj in (self._instances, self._facets, self._sums, self._missing):
            if obj is not None:
                obj.release()
        if self._target is not None:
            for obj in self._target[2:]:
                obj.release()
        if self._mask is not None and self._mask[1] is not None:
            self._mask[1].release()
        for vao, vbo in self._geometry.values():
            vao.release()
            vbo.release()
        self._instances = self._facets = self._sums = self._missing = self._target = self._mask = None
        self._geometry = {}

    # ------------------------------------------------------------------ drawing
    def _render(self, sites, angles, scales, metric: Metric, grid: Grid) -> int:
        n = len(sites)
        coeffs = compile_sites(metric, sites, angles, scales)
        blocks = self._grid_blocks(grid)
        heights = cone_heights(coeffs, scales, metric, blocks)
        self.last_heights = heights
        # margin: float32 geometry must not shave a pixel centre sitting on the boundary
        heights = heights * (1 + 1e-3) + 1e-2 / (scales * metric.inradius)

        if metric.curved and self.mode == "cone":
            radius = float((heights * scales).max()) * metric.circumradius
            segments = ellipse_segments(radius, self.max_error_px)
        elif metric.curved:
            segments = EXACT_FOOTPRINT_SEGMENTS
        else:
            segments = 0
        self.last_segments = segments or None
        facets = 0 if metric.curved or self.mode == "cone" else len(metric.normals)
        varyings = 0 < facets <= self._varying_facets()
        prog = self._program(metric.curved, facets, varyings)
        # keyed by the ball itself: a user's polygon file may be rewritten under one name
        ball = metric.semi_axes if metric.curved else (metric.normals.tobytes(), metric.offsets.tobytes())
        vao_key = (metric.curved, ball, segments, facets, varyings)
        reach = self._vertex_array(vao_key, metric, segments, prog)

        # one power of two maps every depth into [0, 1): scaling by it is exact in float
        top = float(heights.max()) * reach * 1.001
        depth_scale = 2.0 ** -math.ceil(math.log2(top)) if top > 0 else 1.0
        data = np.zeros((n, 10), dtype=np.float32)  # matches "2f 2f 2f 4f/i"
        data[:, 0:2] = sites
        data[:, 2], data[:, 3] = np.cos(angles), np.sin(angles)
        data[:, 4] = scales * heights
        data[:, 5] = heights * depth_scale
        if coeffs.curved:
            data[:, 6:9] = coeffs.quad
        self._upload_instances(np.ascontiguousarray(data))
        if self.mode == "exact" and not coeffs.curved:
            # in the order of the faces: the face-local path reads a face's neighbours
            self._upload_facets(coeffs.facets[:, face_facets(metric)].astype(np.float32))

        fbo = self._framebuffer(grid.width, grid.height)
        ctx = self.ctx
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable_only(self._moderngl.DEPTH_TEST)
        ctx.depth_func = "<"
        prog["u_raster"] = (float(grid.width), float(grid.height))
        if "u_depth_scale" in prog:
            prog["u_depth_scale"] = depth_scale
        vao = self._geometry[vao_key][0]
        vao.render(self._moderngl.TRIANGLES, instances=n)
        return n

    @property
    def _moderngl(self):
        import moderngl

        return moderngl

    def _program(self, curved: bool, facets: int, varyings: bool):
        """The drawing program; in exact mode one per kind and, for polygons, per facet
        count K (the loops' bound is a constant, so the compiler unrolls them) and per
        path of the facets (flat varyings or the storage buffer per fragment)."""
        key = (self.mode, curved, facets, varyings)
        if key not in self._programs:
            if self.mode == "cone":
                frag, vert = _CONE_FRAGMENT_SHADER, _VERTEX_SHADER
            else:
                define = "#define ELLIPSE\n" if curved else f"#define FACETS {facets}\n"
                if not curved:
                    define += "#define FACET_VARYINGS\n" if varyings else "#define FACE_FACETS\n"
                frag = _EXACT_FRAGMENT_SHADER.replace("#version 430\n", "#version 430\n" + define, 1)
                vert = _VERTEX_SHADER.replace("#version 430\n", "#version 430\n" + define, 1)
            self._programs[key] = self.ctx.program(vertex_shader=vert, fragment_shader=frag)
        return self._programs[key]

    def _varying_facets(self) -> int:
        """How many facets the flat varyings carry: two per vec4 slot, less the slots of
        v_id, v_site, v_c0 and one for gl_Position."""
        info = self.ctx.info
        slots = min(
            info.get("GL_MAX_VERTEX_OUTPUT_COMPONENTS", 64), info.get("GL_MAX_FRAGMENT_INPUT_COMPONENTS", 64)
        )
        return 2 * max(slots // 4 - 4, 0)

    def _sums_program(self):
        if self._moments_program is None:
            self._moments_program = self.ctx.compute_shader(_MOMENTS_SHADER)
        return self._moments_program

    def _vertex_array(self, key, metric: Metric, segments: int, prog) -> float:
        """The cone's vertex array (cached per metric and segment count); returns the
        footprint's reach beyond the unit ball."""
        if key not in self._geometry:
            verts, reach = cone_vertices(metric, segments)
            vbo = self.ctx.buffer(verts.tobytes())
            self._ensure_instances(1)
            vao = self.ctx.vertex_array(
                prog,
                [
                    (vbo, "3f", "in_vert"),
                    (self._instances, "2f 2f 2f 4f/i", "in_site", "in_rot", "in_size", "in_c0"),
                ],
                skip_errors=True,
            )
            vao.reach = reach
            self._geometry[key] = (vao, vbo)
        return self._geometry[key][0].reach

    def _ensure_instances(self, nbytes: int):
        if self._instances is None:
            self._instances = self.ctx.buffer(reserve=max(nbytes, 1 << 16), dynamic=True)

    def _upload_instances(self, data: np.ndarray):
        self._ensure_instances(data.nbytes)
        if self._instances.size < data.nbytes:
            # orphaning keeps the buffer object, so the cached vertex arrays stay valid
            self._instances.orphan(max(data.nbytes, 2 * self._instances.size))
        self._instances.write(data.tobytes())

    def _upload_facets(self, facets: np.ndarray):
        """The (N, K, 2) float32 facets into the storage buffer at binding 2."""
        if self._facets is None or self._facets.size < facets.nbytes:
            if self._facets is not None:
                self._facets.release()
            self._facets = self.ctx.buffer(reserve=max(facets.nbytes, 1 << 16), dynamic=True)
        self._facets.write(np.ascontiguousarray(facets).tobytes())
        self._facets.bind_to_storage_buffer(2)

    def _framebuffer(self, w: int, h: int):
        if self._target is not None and self._target[:2] == (w, h):
            return self._target[4]
        limit = min(self.ctx.info["GL_MAX_TEXTURE_SIZE"], *self.ctx.info["GL_MAX_VIEWPORT_DIMS"])
        if w > limit or h > limit:
            raise InputError(f"raster {w}x{h} exceeds this GL driver's limit of {limit} pixels a side")
        if self._target is not None:
            for obj in self._target[2:]:
                obj.release()
        colour = self.ctx.texture((w, h), 1, dtype="u4")
        colour.filter = (self._moderngl.NEAREST, self._moderngl.NEAREST)
        depth = _depth32f_texture(self.ctx, (w, h))
        fbo = self.ctx.framebuffer(color_attachments=[colour], depth_attachment=depth)
        self._target = (w, h, colour, depth, fbo)
        return fbo

    def _mask_texture(self, grid: Grid):
        if grid.mask is None:
            return None
        if (
            self._mask is not None
            and self._mask[0] is not None
            and self._mask[0].shape == grid.mask.shape
            and np.array_equal(self._mask[0], grid.mask)
        ):
            return self._mask[1]
        if self._mask is not None and self._mask[1] is not None:
            self._mask[1].release()
        tex = self.ctx.texture(
            (grid.width, grid.height), 1, grid.mask.astype(np.uint8).tobytes(), dtype="u1", alignment=1
        )
        tex.filter = (self._moderngl.NEAREST, self._moderngl.NEAREST)
        self._mask = (grid.mask.copy(), tex)
        return tex

    def _grid_blocks(self, grid: Grid) -> _Blocks:
        key = (grid.width, grid.height)
        if self._blocks is not None:
            (okey, omask), blocks = self._blocks
            same_mask = (omask is None and grid.mask is None) or (
                omask is not None and grid.mask is not None and np.array_equal(omask, grid.mask)
            )
            if okey == key and same_mask:
                return blocks
        blocks = _Blocks(grid, self.block)
        self._blocks = ((key, None if grid.mask is None else grid.mask.copy()), blocks)
        return blocks

    @staticmethod
    def _check_covered(missing: int):
        if missing:
            raise RuntimeError(
                f"gl backend: {missing} region pixels were reached by no cone (cone heights too small: a bug)"
            )


__all__ = [
    "MODES",
    "ELLIPSE_SEGMENTS",
    "EXACT_FOOTPRINT_SEGMENTS",
    "RUN_LENGTH",
    "SUM_WORDS",
    "shared_context",
    "ellipse_height_error",
    "ellipse_segments",
    "cone_vertices",
    "face_facets",
    "box_max_distance",
    "cone_heights",
    "GLBackend",
]

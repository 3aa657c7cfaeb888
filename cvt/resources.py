"""Memory: what a configuration will need, estimated before anything large is allocated.

Every command that can be asked for more than a machine has (a run, a mosaic, a sweep's
configurations, a picture to decode, a canvas to draw) adds up an :class:`Estimate` from
the sizes it knows beforehand (raster, sites, a picture's declared size, the canvas) and
calls :meth:`Estimate.check`: beyond the limit it raises :class:`ResourceError` (an
InputError: one line, exit status 2) that names the estimate, the limit and how to ask
for less.  The limit is the memory this machine has available now (``MemAvailable``,
capped by a cgroup's limit and ``ulimit -v``), or what ``--memory-limit`` (the
``memory_limit`` argument of the Python API) sets.

An estimate holds two kinds of figures: ``parts``, held for the whole run (the
backend's rasters, the problem's images, the placed elements), which add up, and
``stages``, held only while one step runs (placing, a method's own step such as
compaction, the pictures), of which only the largest counts: the steps run one after
another.  The figures per pixel and per site are peak resident memory measured on this
suite (one process per configuration, its own high-water mark after exec) and rounded
up; the tests compare the estimates with measured peaks.
"""

from __future__ import annotations

import math
import os
import resource
from dataclasses import dataclass, field

from .errors import InputError
from .metrics import Depth
from .validate import byte_size

MiB = 2**20
PROGRAM = 120 * MiB  # the interpreter with numpy, scipy, shapely, Pillow and matplotlib loaded
RUNTIME = 240 * MiB  # a backend's runtime (LLVM, a first kernel build) where its class does not say

# bytes per pixel of the raster (float64 images, int32 labels, their temporaries) ...
PER_PIXEL = {
    "density": 40,  # the image at raster size, the density map, its clip and acceptance
    "field": 24,  # the image at raster size and the angles
    "region": 14,  # the mask and its resampling
    "seeding": 8,  # the region's pixel indices (without a region none are made)
    "placement": 24,  # mosaics: contour samples and their reach, the region, the evaluation
    "pictures": 12,  # cells.png's colour per pixel, elements.png drawn in bands
    "labels": 48,  # a backend that does not say: labels and moments on the host
    # a mosaic's picture at raster size (float32), its fields, and while they are made the
    # tensor's results and one complex spectrum (the tensor itself a band of rows at a time)
    "picture": 64,
    "colours": 16,  # the tiles' fills: their pixels found and read a run of tiles at a time
}
# ... and per site (coefficients, the placed polygon, its outline in result.json)
PER_SITE = {"polygon": 1_000, "curved": 4_000}  # a 128-gon outline costs ~2.5 kB in GEOS
SUPERSAMPLE = 3  # cvt.render.draw_elements' default
# placing: each contour sample (cvt.placement, two per edge between cells) with its sort
# and reach; a cell of A pixels has about 4.5·sqrt(A) of them
CONTOUR_SAMPLE = 48
CONTOUR_SAMPLES_PER_SITE = 4.5
# moving elements inside their cells (fit): the distance transform of the cells, by the
# shape record's distance (chessboard: int32; the others: float64 and its feature indices)
FIT_PER_PIXEL = {Depth.CHESSBOARD: 6, Depth.SCALED: 18, Depth.EUCLIDEAN: 18}


class ResourceError(InputError):
    """A configuration that needs more memory than the limit allows."""


def format_bytes(n: float) -> str:
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n / 2**10:.3g} KiB"


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _read_int(path: str) -> int | None:
    try:
        with open(path) as fh:
            text = fh.read().strip()
        return None if text in ("", "max") else int(text)
    except (OSError, ValueError):
        return None


def _cgroup_left() -> int | None:
    """What the memory cgroup of this process still allows (v2, then v1), if it limits."""
    for limit_file, usage_file in (
        ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
        ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"),
    ):
        limit, usage = _read_int(limit_file), _read_int(usage_file)
        if limit is not None and limit < 2**60:  # v1 says "no limit" with a huge number
            return max(0, limit - (usage or 0))
    return None


def available_memory() -> tuple[int, str]:
    """(bytes, what they are) that this process may still use: the least of the
    machine's available memory, a cgroup's limit and the address-space limit."""
    found = []
    avail = _meminfo_available()
    if avail is None:
        try:
            avail = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (OSError, ValueError, AttributeError):
            avail = None
    if avail is not None:
        found.append((avail, "the memory available on this machine"))
    left = _cgroup_left()
    if left is not None:
        found.append((left, "the memory left under this container's limit"))
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        found.append((soft, "the address-space limit (ulimit -v)"))
    return min(found) if found else (4 * 2**30, "an assumed 4 GiB (the machine's memory is unknown)")


def memory_limit(limit=None, name: str = "--memory-limit") -> tuple[int, str]:
    """(bytes, what they are): ``limit`` (a size such as ``8G``) when given, else
    :func:`available_memory`."""
    if limit is None:
        return available_memory()
    return byte_size(limit, name), f"the limit {name} sets"


@dataclass
class Estimate:
    """Peak memory of one piece of work, as named parts added to the program's own."""

    what: str  # "this run", "the mosaic", ...
    parts: dict[str, float] = field(default_factory=dict)  # held throughout: they add up
    stages: dict[str, float] = field(default_factory=dict)  # one at a time: the largest counts

    def add(self, name: str, nbytes: float) -> Estimate:
        """Add ``nbytes`` held for the whole run to the part ``name``."""
        self.parts[name] = self.parts.get(name, 0.0) + max(0.0, float(nbytes))
        return self

    def stage(self, name: str, nbytes: float) -> Estimate:
        """Add ``nbytes`` held only while the step ``name`` runs."""
        self.stages[name] = self.stages.get(name, 0.0) + max(0.0, float(nbytes))
        return self

    @property
    def held(self) -> float:
        """The parts and the largest stage (all but the program itself)."""
        return sum(self.parts.values()) + max(self.stages.values(), default=0.0)

    @property
    def total(self) -> float:
        return PROGRAM + self.held

    def check(self, limit=None, *, lower: str, name: str = "--memory-limit") -> Estimate:
        """Raise ResourceError when the estimate exceeds the limit (see :func:`memory_limit`);
        ``lower`` says how to ask for less, ``name`` is the option that raises the limit."""
        allowed, source = memory_limit(limit, name)
        if self.total > allowed:
            named = {**self.parts, **self.stages}
            top = max(named, key=named.get) if named else "the program"
            raise ResourceError(
                f"{self.what} needs about {format_bytes(self.total)} of memory (of which {top} "
                f"{format_bytes(named.get(top, PROGRAM))}), more than {source} "
                f"({format_bytes(allowed)}); {lower}, or set {name} higher if the memory is there"
            )
        return self


# the fidelity measures (centroids, the Delaunay triangulation, the neighbour pairs):
# measured 0.7-0.8 kB a site (73 728 circles, 16 000 squares); `cvtbench run` takes them
# beside its pictures
MEASURES_PER_SITE = 1000


def element_bytes(n_elements: int, element: str | None) -> float:
    """The placed elements (GEOS polygons) and their outlines while they are written."""
    from .shapes import shape_record

    curved = element is not None and shape_record(element).curved
    return PER_SITE["curved" if curved else "polygon"] * n_elements


def placement_bytes(pixels: int, n_elements: int, element: str | None) -> float:
    """Placing one element per cell, evaluating them and keeping their outlines."""
    return PER_PIXEL["placement"] * pixels + element_bytes(n_elements, element)


def contour_bytes(pixels: int, n_elements: int) -> float:
    """The contour samples of ``n_elements`` cells of a raster of ``pixels`` (at most
    four per pixel), while elements are placed in the cells."""
    samples = min(CONTOUR_SAMPLES_PER_SITE * math.sqrt(float(n_elements) * pixels), 4.0 * pixels)
    return CONTOUR_SAMPLE * samples


def canvas_bytes(width: int, height: int, scale: float = 1.0, supersample: int = SUPERSAMPLE) -> float:
    """An RGB picture of the raster drawn ``supersample`` times larger and reduced
    (Pillow keeps 4 bytes per RGB pixel), and its PNG encoding."""
    big = math.ceil(width * scale * supersample) * math.ceil(height * scale * supersample)
    small = math.ceil(width * scale) * math.ceil(height * scale)
    return 4.0 * big + 12.0 * small


def run_estimate(
    width: int,
    height: int,
    n_elements: int,
    backend_class,
    *,
    element: str | None = None,
    density: bool = False,
    field: bool = False,
    region: bool = False,
    placement: bool = True,
    pictures: bool = True,
    method=None,
    what: str = "this run",
) -> Estimate:
    """The peak memory of one run of a method on ``backend_class``.

    Held throughout: the backend's runtime, labels and moments, the problem's images at
    raster size and, with ``placement``, the placed elements.  One at a time: seeding
    within a region, placing the elements in their cells (contour samples), the
    method's own step and, with ``pictures``, the pictures of ``cvtbench run`` with the
    fidelity measures it takes beside them.

    Parameters
    ----------
    width, height, n_elements : int
        The raster and the number of sites.
    backend_class : type
        The backend (its ``runtime_bytes`` and ``memory_estimate``).
    element : str or None
        The element shape (curved outlines cost more; the fit's distance transform).
    density, field, region : bool
        Whether the problem has these images.
    placement, pictures : bool
        Whether elements are placed, and whether ``cvtbench run``'s pictures are drawn.
    method : Method or None
        The method record: ``fits`` adds the fit's distance transform, ``memory`` its
        own step (given the raster's pixels, the sites, the element and ``density``).
    what : str
        How the refusal names the work.

    Returns
    -------
    Estimate
    """
    from .shapes import shape_record

    pixels = width * height
    est = Estimate(what)
    est.add("the backend's runtime", getattr(backend_class, "runtime_bytes", RUNTIME))
    backend_bytes = getattr(backend_class, "memory_estimate", None)
    est.add(
        "the backend's labels and moments",
        backend_bytes(width, height, n_elements) if backend_bytes else PER_PIXEL["labels"] * pixels,
    )
    for name, used in (("density", density), ("field", field), ("region", region)):
        if used:
            est.add(f"the {name} image", PER_PIXEL[name] * pixels)
    if region:
        est.stage("seeding", PER_PIXEL["seeding"] * pixels)
    if placement:
        est.add("the elements", element_bytes(n_elements, element))
        fit = getattr(method, "fits", False) and element is not None
        distance = shape_record(element).distance if fit else None
        est.stage(
            "placing the elements",
            contour_bytes(pixels, n_elements) + FIT_PER_PIXEL.get(distance, 0) * pixels,
        )
        own = getattr(method, "memory", None)
        if own is not None:
            step, nbytes = own(pixels, n_elements, element, density)
            est.stage(step, nbytes)
    if pictures:
        est.stage(
            "the pictures and the measures taken beside them",
            PER_PIXEL["pictures"] * pixels + MEASURES_PER_SITE * n_elements,
        )
    return est


def mosaic_estimate(
    width: int,
    height: int,
    n_elements: int,
    backend_class,
    *,
    element: str | None = None,
    png_scale: float | None = None,
    compare: bool = False,
    what: str = "the mosaic",
) -> Estimate:
    """The peak memory of a mosaic: the picture and its fields at raster size, a run
    with density and field, the colours and, with ``png_scale``, mosaic.png; a
    comparison (``compare``) runs a second mosaic while the first is kept."""
    pixels = width * height
    est = run_estimate(
        width,
        height,
        n_elements,
        backend_class,
        element=element,
        density=True,
        field=True,
        placement=False,
        pictures=False,
        what=what,
    )
    est.add("seeding", PER_PIXEL["seeding"] * pixels)
    est.add("placing and evaluating the elements", placement_bytes(pixels, n_elements, element))
    est.add("the picture and its fields", PER_PIXEL["picture"] * pixels)
    est.add("the colours", PER_PIXEL["colours"] * pixels)
    if compare:
        est.add("the second mosaic of the comparison", est.held)
        est.add("the comparison picture", 3 * canvas_bytes(width, height))
    if png_scale is not None:
        est.add("mosaic.png", canvas_bytes(width, height, png_scale))
    return est


__all__ = [
    "mosaic_estimate",
    "Estimate",
    "ResourceError",
    "available_memory",
    "memory_limit",
    "run_estimate",
    "placement_bytes",
    "element_bytes",
    "contour_bytes",
    "RUNTIME",
    "CONTOUR_SAMPLE",
    "CONTOUR_SAMPLES_PER_SITE",
    "MEASURES_PER_SITE",
    "FIT_PER_PIXEL",
    "canvas_bytes",
    "format_bytes",
    "PROGRAM",
]

"""Size buckets: the kernels of a solve compile once per bucket of image sizes
(lss_kernels.kernels.backend.bucket_shape), not once per size, save the few that keep the
float code of one size (the upward pass, the ray cast, the set-up's sums of children)."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from lss_kernels.kernels.backend import bucket_shape, bucket_size
from lss_kernels.reference import kernels as ref


def test_bucket_sides_are_half_octaves_from_64():
    sides = [64, 96, 128, 192, 256, 384, 512, 768, 1024, 1536, 2048, 3072]
    assert [bucket_size(n) for n in sides] == sides
    assert [bucket_size(n + 1) for n in sides[:-1]] == sides[1:]
    assert bucket_size(1) == 64
    assert bucket_shape(1500, 2000) == (1536, 2048)
    for n in range(1, 5000, 7):
        b = bucket_size(n)
        assert n <= b <= max(64, 1.5 * n) and b % 32 == 0
    with pytest.raises(ValueError):
        bucket_size(0)


def test_bucket_fields_live_in_a_tree_of_their_own(ti_arch):
    import taichi as ti
    from lss_kernels.kernels.backend import FieldPool
    pool = FieldPool()
    try:
        plain = pool.field(ti.f32, (3, 5))
        inside = pool.vector(2, ti.u32, (4, 6), bucket=True)
        with pytest.raises(ValueError):
            pool.field(ti.f32, (2,), volume=True, bucket=True)
        pool.finalize()
        tree = lambda f: f.snode.ptr.get_snode_tree_id()
        assert tree(plain) != tree(inside)
        assert sorted((tree(plain), tree(inside))) == sorted(t.id for t in pool._trees)
        assert pool.nbytes == 3 * 5 * 4 + 4 * 6 * 8
    finally:
        pool.destroy()


def test_a_pool_destroyed_before_any_kernel_ran_leaves_nothing_behind(ti_arch):
    """Taichi reads the shapes of the vector fields declared since its last compile at the
    next one: those of a pool destroyed in between must not be among them (reading them can
    crash the process)."""
    import taichi as ti
    from lss_kernels.kernels.backend import FieldPool
    pool = FieldPool()
    vectors = [pool.vector(3, ti.f32, (5, 7), bucket=True), pool.vector(2, ti.f32, (5, 7))]
    pool.field(ti.f32, (5, 7))
    pool.finalize()
    pending = lambda: {id(f) for f in ti.lang.impl.get_runtime().matrix_fields}
    assert {id(f) for f in vectors} <= pending()          # what the test is about
    pool.destroy()
    assert not {id(f) for f in vectors} & pending()
    other = FieldPool()
    v = other.vector(2, ti.f32, (3, 4))
    other.finalize()
    try:
        v.from_numpy(np.ones((3, 4, 2), np.float32))          # compiles a kernel
        assert v.to_numpy().sum() == 24
    finally:
        other.destroy()


# Two sizes of the bucket 64x64, each followed by backend.restart, as `lss eval` builds its
# solvers: the restart writes the offline cache of the program it ends, so the .tic files
# after each size are the kernels compiled so far.  Besides the median and the census, the
# level set (derivatives, re-initialisation, the median's settle into phi and D, the net
# change), the shapes' fit and the occlusion geometry run on planes of the bucket; the ray
# cast compiles once per size (its float code must stay that of one size), which shows that
# a kernel compiled again is seen.
BUCKET_SCRIPT = r"""
import json, sys
from pathlib import Path
import numpy as np
import taichi as ti
from lss_kernels.kernels import backend
from lss_kernels.kernels.backend import FieldPool
from lss_kernels.kernels.median import Assign, MedianFilter
from lss_kernels.model.levelset import LevelSet
from lss_kernels.model.matching import MatchingCost
from lss_kernels.model.occlusion import OcclusionGeometry
from lss_kernels.model.shapes import GlobalShapes, WeightPlanes
from lss_kernels.params import Params

cache, out = Path(sys.argv[1]), Path(sys.argv[2])
kernels = sys.argv[3].split(",")
backend.init("cpu", threads=1, offline_cache=True)
rng = np.random.default_rng(5)
results, entries = {}, []
for h, w in ((37, 53), (45, 61)):
    plane = np.round(rng.standard_normal((h, w)) * 2).astype(np.float32)
    image = (np.round(rng.random((h, w, 3)) * 4) / 4).astype(np.float32)
    y, x = np.mgrid[0:h, 0:w]
    phi = ((12.0 - np.hypot(x - w / 2, y - h / 2)) / 10.0).astype(np.float32)
    pool = FieldPool()
    # two 7x7 filters in one pool, as in a solver (the level set's and the initialiser's)
    medians = [MedianFilter(pool, h, w, 7) for _ in range(2)]
    assert medians[0]._tree is medians[1]._tree
    matcher = MatchingCost(pool, h, w, "ad_census")
    src, dst = pool.field(ti.f32, (h, w)), pool.field(ti.f32, (h, w))
    img = pool.vector(3, ti.f32, (h, w))
    ls = LevelSet(pool, h, w, Params())
    shapes = GlobalShapes(pool, h, w)
    occ = OcclusionGeometry(pool, h, w, 8)
    bucket = ls.extent.bucket
    weight_fg, weight_bg, target = (pool.field(ti.f32, bucket, bucket=True) for _ in range(3))
    pool.finalize()
    ls.setup()
    src.from_numpy(plane)
    img.from_numpy(image)
    medians[0].run(src, Assign(dst))
    results[f"median{h}x{w}"] = dst.to_numpy()
    medians[1].run(src, Assign(src))                    # in place, as the initialiser does
    results[f"median_in_place{h}x{w}"] = src.to_numpy()
    matcher.setup(img, img)
    results.update({f"plane{h}x{w}": plane, f"image{h}x{w}": image,
                    f"census{h}x{w}": matcher.census_words(0),
                    f"census_right{h}x{w}": matcher.census_words(1)})
    ls.phi.from_numpy(ls.extent.padded(phi))
    ls.reinitialise(ls.phi)
    ls.net_change()
    ls.derivatives()
    weight_fg.from_numpy(ls.extent.padded((phi > 0).astype(np.float32)))
    weight_bg.from_numpy(ls.extent.padded((phi <= 0).astype(np.float32)))
    target.from_numpy(ls.extent.padded((4.0 + 0.1 * x + 2.0 * (phi > 0)).astype(np.float32)))
    shapes.fit(WeightPlanes(weight_fg, weight_bg), target)
    occ.compute(shapes, ls.phi_x, 1)
    occ.refresh_phi_plus(ls.phi)
    occ.render_left(shapes, ls.phi)
    ls.phi_next.from_numpy(ls.extent.padded(plane))
    ls.settle(shapes)
    results[f"settled{h}x{w}"] = ls.extent.image(ls.phi)
    ls.destroy()
    pool.destroy()
    backend.restart()
    seen = {}
    for path in cache.rglob("*.tic"):
        text = path.read_bytes()
        for kernel in kernels:
            if f'"name":"{kernel}_c'.encode() in text:
                seen.setdefault(kernel, []).append(path.name)
    entries.append(seen)
np.savez(out, **results)
print(json.dumps(entries))
"""

#: Kernels of the script that compile once per size bucket, each launched once per size.
BUCKET_KERNELS = ("_merge", "_bucket_census", "_derivatives", "fit",
                  "refresh_phi_plus", "render_left", "_distance_step", "net_change",
                  "_pass")


@pytest.fixture(scope="module")
def two_sizes(tmp_path_factory, ti_arch):
    """The median, the census, the level set's results and the offline-cache entries after
    each of two sizes of one bucket, in a fresh process with an empty cache."""
    if ti_arch != "cpu":
        pytest.skip("the offline cache is exercised on the CPU")
    tmp = tmp_path_factory.mktemp("buckets")
    cache = tmp / "cache"
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(cache))
    kernels = BUCKET_KERNELS + ("_sort", "_store", "_ray_cast")
    proc = subprocess.run([sys.executable, "-c", BUCKET_SCRIPT, str(cache),
                           str(tmp / "out.npz"), ",".join(kernels)], env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    entries = json.loads(proc.stdout.splitlines()[-1])
    return entries, dict(np.load(tmp / "out.npz"))


def _census_words(image):
    bits = ref.census(image.astype(np.float64)).astype(np.uint32)
    words = np.zeros(bits.shape[:2] + (2,), np.uint32)
    for bit in range(bits.shape[-1]):
        words[..., bit // 32] |= bits[..., bit] << np.uint32(bit % 32)
    return words


def test_sizes_of_one_bucket_give_the_references_bit_for_bit(two_sizes):
    _, out = two_sizes
    for size in ("37x53", "45x61"):
        want = ref.median_filter(out[f"plane{size}"], 7)
        np.testing.assert_array_equal(out[f"median{size}"], want)
        np.testing.assert_array_equal(out[f"median_in_place{size}"], want)
        np.testing.assert_array_equal(out[f"settled{size}"], want)
        words = _census_words(out[f"image{size}"])
        np.testing.assert_array_equal(out[f"census{size}"], words)
        np.testing.assert_array_equal(out[f"census_right{size}"], words)


def test_a_second_size_of_a_bucket_compiles_none_of_the_bucket_kernels(two_sizes):
    """The bucketed kernels' cache entries after the second size are those of the first (one
    median tree for both filters); the ray cast, compiled once per size, shows that a
    kernel compiled again is seen.  The median's sort and store compile again only for the
    test's own planes of the size's shape (the source ``src``; the sinks into ``dst`` and
    ``src``), not for the level set's planes of the bucket."""
    (first, second), _ = two_sizes
    for kernel in BUCKET_KERNELS:
        assert kernel in first, (kernel, first)
        assert second[kernel] == first[kernel], (kernel, first, second)
    assert len(first["_ray_cast"]) == 1 and len(second["_ray_cast"]) == 2, (first, second)
    assert len(first["_sort"]) == 2 and len(second["_sort"]) == 3, (first, second)
    assert len(first["_store"]) == 3 and len(second["_store"]) == 5, (first, second)


def test_filters_of_a_pool_share_the_tree_of_their_window(ti_arch):
    import taichi as ti
    from lss_kernels.kernels.backend import FieldPool
    from lss_kernels.kernels.median import SCRATCH, MedianFilter
    pool = FieldPool()
    a, b, c = (MedianFilter(pool, 30, 40, k) for k in (7, 7, 5))
    other = MedianFilter(pool, 100, 40, 7)                  # another bucket
    taller = MedianFilter(pool, SCRATCH[0] + 1, 40, 7)      # beyond the scratch
    pool.field(ti.f32, (1,))
    pool.finalize()
    try:
        assert a._tree is b._tree and other._tree is a._tree
        assert c._tree is not a._tree and taller._tree is not a._tree
        assert a.bucket == (64, 64) and other.bucket == (128, 64)
    finally:
        pool.destroy()


# One median filter at sizes of two buckets, and one taller than the merge tree's scratch,
# each followed by backend.restart (which writes the offline cache): the .tic files that
# hold the tree's kernel after each size.
MERGE_SCRIPT = r"""
import json, sys
from pathlib import Path
import numpy as np
import taichi as ti
from lss_kernels.kernels import backend
from lss_kernels.kernels.backend import FieldPool
from lss_kernels.kernels.median import SCRATCH, Assign, MedianFilter

cache, out = Path(sys.argv[1]), Path(sys.argv[2])
backend.init("cpu", threads=1, offline_cache=True)
rng = np.random.default_rng(9)
results, entries = {}, []
for h, w in ((37, 53), (150, 100), (SCRATCH[0] + 9, 21)):
    pool = FieldPool()
    extent = pool.extent(h, w)
    src = pool.field(ti.f32, extent.bucket, bucket=True)
    dst = pool.field(ti.f32, extent.bucket, bucket=True)
    median = MedianFilter(pool, h, w, 7)
    pool.finalize()
    plane = np.round(rng.standard_normal((h, w)) * 2).astype(np.float32)
    src.from_numpy(extent.padded(plane))
    median.run(src, Assign(dst))
    results[f"plane{h}x{w}"] = plane
    results[f"median{h}x{w}"] = extent.image(dst)
    pool.destroy()
    backend.restart()
    entries.append(sorted(p.name for p in cache.rglob("*.tic")
                          if b'"name":"_merge_c' in p.read_bytes()))
np.savez(out, **results)
print(json.dumps(entries))
"""


def test_the_median_tree_compiles_once_for_every_bucket_that_fits_its_scratch(tmp_path,
                                                                               ti_arch):
    """Its cache entry after a second bucket is the first bucket's; an image taller than
    :data:`~lss_kernels.kernels.median.SCRATCH` compiles it again.  The medians are the
    reference's at every size."""
    if ti_arch != "cpu":
        pytest.skip("the offline cache is exercised on the CPU")
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(tmp_path / "cache"))
    proc = subprocess.run([sys.executable, "-c", MERGE_SCRIPT, str(tmp_path / "cache"),
                           str(tmp_path / "out.npz")], env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    small, other_bucket, taller = json.loads(proc.stdout.splitlines()[-1])
    assert len(small) == 1 and other_bucket == small, (small, other_bucket)
    assert len(taller) == 2, taller
    out = dict(np.load(tmp_path / "out.npz"))
    for name in (n for n in out if n.startswith("plane")):
        size = name[len("plane"):]
        np.testing.assert_array_equal(out[f"median{size}"],
                                      ref.median_filter(out[name], 7))


# Whole solves at two sizes of one bucket (96x128) and one search range, as `lss eval` runs
# them (a restart between): the names of the kernels whose cache entries the second adds.
SOLVER_SCRIPT = r"""
import json, re, sys
from pathlib import Path
from lss_kernels import Params, Solver
from lss_kernels.kernels import backend
from lss_kernels.scenes import make_scene

cache = Path(sys.argv[1])
backend.init("cpu", offline_cache=True)
files = []
for width, height in ((100, 75), (110, 70)):
    scene = make_scene(None, width=width, height=height)
    solver = Solver(scene.left, scene.right, 20.0, scene.init_ellipse,
                    params=Params(max_iterations=12, matching_cost="ad_census"))
    solver.run()
    solver.close()
    backend.restart()
    files.append({p.name: p for p in cache.rglob("*.tic")})
name = re.compile(rb'"name":"([A-Za-z0-9_]+?)_c[0-9]+_[0-9]+')
added = sorted({m.decode() for f in set(files[1]) - set(files[0])
                for m in name.findall(files[1][f].read_bytes())})
print(json.dumps(added))
"""

#: The kernels of a solve that compile once per image size (see
#: lss_kernels.kernels.backend.Extent): they keep the float code of one size (the set-up's
#: volumes, whose sums of children do; the ray cast, with B in the iteration's kernel; the
#: upward pass).  The second list: those of the start's region (model/init.py, here an
#: ellipse read as its box), whose fields have the image's own size, and the pool's transfer
#: kernels, which move such fields.  The median's sort is not one of them: the start's
#: d-bar is filtered from the median's source plane, which is the level set's and in the
#: bucket tree.
PER_SIZE_KERNELS = sorted(["_build_costs", "geometry", "upward"]
                          + ["_region_pass", "_store", "load", "read", "write"])


@pytest.mark.slow
def test_a_second_size_of_a_bucket_recompiles_only_the_per_size_kernels(tmp_path, ti_arch):
    if ti_arch != "cpu":
        pytest.skip("the offline cache is exercised on the CPU")
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(tmp_path / "cache"))
    proc = subprocess.run([sys.executable, "-c", SOLVER_SCRIPT, str(tmp_path / "cache")],
                          env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads(proc.stdout.splitlines()[-1]) == PER_SIZE_KERNELS


def test_an_annex_is_finalised_zeroed_counted_and_destroyed_with_its_pool(ti_arch):
    """An annex's trees come after the pool's (the pool's own trees, and so the keys of the
    kernels that touch only them, do not change with it) and live and die with the pool."""
    import taichi as ti
    from lss_kernels.kernels.backend import FieldPool
    pool = FieldPool()
    a = pool.field(ti.f32, (3, 5), bucket=True)
    annex = pool.annex()
    b = annex.field(ti.i32, (4,))
    extent = annex.extent(7, 9)                         # a loader that runs a kernel
    pool.finalize()
    assert annex.generation == pool.generation
    assert extent.size.to_numpy().tolist() == [7, 9]
    assert pool.nbytes == 3 * 5 * 4 + annex.nbytes and annex.nbytes >= 4 * 4
    a.fill(2.0)
    b.fill(3)
    pool.zero()
    assert not a.to_numpy().any() and not b.to_numpy().any()
    assert extent.size.to_numpy().tolist() == [7, 9]     # the annex's loader ran again
    pool.destroy()
    assert pool._trees == [] and annex._trees == []


def test_a_pool_moves_any_field_of_its_own_or_its_annexes_to_and_from_the_host(ti_arch):
    """FieldPool.read / write (one kernel each for the host fields of a pool and its
    annexes; Taichi's copies for the others) give back exactly what was written, in the
    field's shape and dtype, as Taichi's own copies do."""
    import taichi as ti
    from lss_kernels.kernels.backend import FieldPool
    pool = FieldPool()
    rng = np.random.default_rng(1)
    cases = [(pool.field(ti.f32, (3, 5), bucket=True), rng.standard_normal((3, 5))),
             (pool.field(ti.i32, (4,)), np.array([-2 ** 31, 7, 2 ** 31 - 1, 0])),
             (pool.field(ti.i8, (2, 3), volume=True), np.array([[-128, 0, 127], [1, -1, 5]])),
             (pool.field(ti.f32, ()), np.array(1.0 / 3.0)),
             (pool.vector(3, ti.f32, (2, 4), bucket=True), rng.random((2, 4, 3))),
             (pool.vector(2, ti.i32, ()), np.array([3, -4])),
             (pool.field(ti.f32, (4, 3), offset=(-1, -2)), rng.random((4, 3)))]
    annex = pool.annex()
    cases.append((annex.field(ti.u8, (6,), bucket=True), np.arange(250, 256)))
    pool.host(*(f for f, _ in cases[1:]))       # the first is not a host field
    pool.finalize()
    try:
        for f, values in cases:
            pool.write(f, values)
        for f, values in cases:
            got = pool.read(f)
            want = f.to_numpy()
            assert got.dtype == want.dtype and got.shape == want.shape == values.shape
            np.testing.assert_array_equal(got, want)
            np.testing.assert_array_equal(got, values.astype(want.dtype))
        with pytest.raises(ValueError, match="shape"):
            pool.write(cases[0][0], np.zeros((5, 3)))
        other = FieldPool()
        stranger = other.field(ti.f32, (2,))
        other.finalize()
        with pytest.raises(ValueError, match="not one of this pool's"):
            pool.read(stranger)
        other.destroy()
    finally:
        pool.destroy()


def test_a_field_marked_for_the_host_after_a_transfer_is_moved_by_new_kernels(ti_arch):
    import taichi as ti
    from lss_kernels.kernels.backend import FieldPool
    pool = FieldPool()
    early, late = pool.field(ti.f32, (2, 3), bucket=True), pool.field(ti.i32, (4,))
    pool.host(early)
    pool.finalize()
    try:
        pool.write(early, np.full((2, 3), 1.5))
        first = pool._io
        pool.host(late)
        pool.write(late, np.arange(4))
        assert pool._io is not first and pool._io_index[id(late)] is not None
        np.testing.assert_array_equal(pool.read(late), np.arange(4))
        np.testing.assert_array_equal(pool.read(early), np.full((2, 3), 1.5, np.float32))
    finally:
        pool.destroy()

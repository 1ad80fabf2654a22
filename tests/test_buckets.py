"""Size buckets: the median's tree of merge networks and the census transform compile once
per bucket of image sizes (lss_kernels.kernels.backend.bucket_shape), not once per size."""
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
# after each size are the kernels compiled so far.
BUCKET_SCRIPT = r"""
import json, sys
from pathlib import Path
import numpy as np
import taichi as ti
from lss_kernels.kernels import backend
from lss_kernels.kernels.backend import FieldPool
from lss_kernels.kernels.median import Assign, MedianFilter
from lss_kernels.model.matching import MatchingCost

cache, out = Path(sys.argv[1]), Path(sys.argv[2])
backend.init("cpu", threads=1, offline_cache=True)
rng = np.random.default_rng(5)
results, entries = {}, []
for h, w in ((37, 53), (45, 61)):
    plane = np.round(rng.standard_normal((h, w)) * 2).astype(np.float32)
    image = (np.round(rng.random((h, w, 3)) * 4) / 4).astype(np.float32)
    pool = FieldPool()
    # two 7x7 filters in one pool, as in a solver (the level set's and the initialiser's)
    medians = [MedianFilter(pool, h, w, 7) for _ in range(2)]
    assert medians[0]._tree is medians[1]._tree
    matcher = MatchingCost(pool, h, w, "ad_census")
    src, dst = pool.field(ti.f32, (h, w)), pool.field(ti.f32, (h, w))
    img = pool.vector(3, ti.f32, (h, w))
    pool.finalize()
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
    pool.destroy()
    backend.restart()
    seen = {}
    for path in cache.rglob("*.tic"):
        text = path.read_bytes()
        for kernel in ("_bucket_median", "_bucket_census", "_store"):
            if f'"name":"{kernel}_c'.encode() in text:
                seen.setdefault(kernel, []).append(path.name)
    entries.append(seen)
np.savez(out, **results)
print(json.dumps(entries))
"""


@pytest.fixture(scope="module")
def two_sizes(tmp_path_factory, ti_arch):
    """The median, the census and the offline-cache entries after each of two sizes of one
    bucket, in a fresh process with an empty cache."""
    if ti_arch != "cpu":
        pytest.skip("the offline cache is exercised on the CPU")
    tmp = tmp_path_factory.mktemp("buckets")
    cache = tmp / "cache"
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(cache))
    proc = subprocess.run([sys.executable, "-c", BUCKET_SCRIPT, str(cache),
                           str(tmp / "out.npz")], env=env, capture_output=True, text=True,
                          timeout=600)
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
        words = _census_words(out[f"image{size}"])
        np.testing.assert_array_equal(out[f"census{size}"], words)
        np.testing.assert_array_equal(out[f"census_right{size}"], words)


def test_a_second_size_of_a_bucket_compiles_neither_median_nor_census(two_sizes):
    """The bucketed kernels' cache entries after the second size are those of the first
    (one median tree for both filters); the filters' per-size store kernels show that a
    kernel compiled again is seen."""
    (first, second), _ = two_sizes
    for kernel in ("_bucket_median", "_bucket_census"):
        assert len(first[kernel]) == 1, (kernel, first)
        assert second[kernel] == first[kernel], (kernel, first, second)
    assert len(first["_store"]) == 2 and len(second["_store"]) == 4, (first, second)


def test_filters_of_a_pool_share_the_tree_of_their_window(ti_arch):
    import taichi as ti
    from lss_kernels.kernels.backend import FieldPool
    from lss_kernels.kernels.median import MedianFilter
    pool = FieldPool()
    a, b, c = (MedianFilter(pool, 30, 40, k) for k in (7, 7, 5))
    other = MedianFilter(pool, 100, 40, 7)                  # another bucket
    pool.field(ti.f32, (1,))
    pool.finalize()
    try:
        assert a._tree is b._tree
        assert c._tree is not a._tree and other._tree is not a._tree
        assert a.bucket == (64, 64) and other.bucket == (128, 64)
    finally:
        pool.destroy()

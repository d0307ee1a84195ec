"""Every compiled loop gives the same bits whether numba compiled it or loaded it from its cache.

A gp_smc study run twice from the same study file and seed must give the same posterior: SMC
amplifies a difference in the last bit of L into a different particle cloud (Monte Carlo
error, not round-off).  With numba's ``reassoc`` fast-math flag the parallel loops of the GP
mean (:mod:`fbia.iterators.surrogates.mean`) and of the product kernel's gradient
(:mod:`fbia.iterators.surrogates.kernels`) summed in one order when numba compiled them and in
another when a later process loaded them from the cache (numba 0.68): study_cpp's MAP moved
from 400.08 to 399.86 Pa between a first run and its rerun from the store.  Here two
processes share an empty cache: the first compiles every loop, the second loads them.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

SCRIPT = r"""
import hashlib
import numpy as np
import fbia
from fbia.iterators.smc.table import LogTables
from fbia.iterators.surrogates.kernels import _product_grad, product_kernel
from fbia.iterators.surrogates.mean import KernelTerms, fused_mean

def digest(v):
    return hashlib.sha1(np.ascontiguousarray(v).tobytes()).hexdigest()

rng = np.random.default_rng(0)
x_train, alpha = rng.standard_normal((965, 2)), rng.standard_normal(965)
x = rng.standard_normal((3000, 2))
out = {}
for product in (False, True):
    terms = KernelTerms.of(product, np.array([0.5, 0.7]), x_train, alpha, 3.0)
    out[f"mean product={product}"] = digest(fused_mean(terms, x))
a, bt = np.ascontiguousarray(x[:500]), np.ascontiguousarray(x_train.T)
out["product_kernel"] = digest(product_kernel(a, bt, 2.0))
out["product_grad"] = digest(_product_grad(a, bt, rng.standard_normal((500, 965))))
priors = [fbia.priors.uniform(100.0, 800.0), fbia.priors.uniform(-0.8, 0.5)]
table = LogTables.build(
    lambda z: -(((z[:, 0] - 400) / 30) ** 2) - ((z[:, 1] - 0.3) / 0.1) ** 2, priors, 257
)
z = rng.uniform(size=(4000, 2)) * [700, 1.3] + [100, -0.8]
out["table L"] = digest(table.log_likelihood(z))
out["table prior"] = digest(table.log_prior(z))
step = np.diag([20.0, 0.05])
moved = table.move(
    z, table.log_likelihood(z), table.log_prior(z), step, 0.5, 10, np.random.default_rng(1)
)
out["table moves"] = digest(moved[0])
for k, v in out.items():
    print(k, v)
"""


def _digests(cache: Path) -> dict[str, str]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, check=True
    )
    return dict(line.rsplit(" ", 1) for line in done.stdout.splitlines())


def test_a_loop_compiled_and_the_same_loop_from_the_cache_give_the_same_bits(
    tmp_path: Path,
) -> None:
    compiled = _digests(tmp_path)
    assert any(tmp_path.rglob("*.nbi")), "the first process wrote no numba cache"
    cached = _digests(tmp_path)
    assert len(compiled) == 7
    differ = [k for k in compiled if compiled[k] != cached[k]]
    assert not differ, f"compiled and cached loops differ in: {', '.join(differ)}"

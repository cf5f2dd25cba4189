"""Tests of experiments.pipeline.jax_cache: where the cache goes, 'off', and a
second process loading what the first compiled."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import jax

from experiments.pipeline import jax_cache

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

# A process that enables the cache in argv[1], compiles one program and
# reports the persistent cache's hits.
_CHILD = r"""
import json, sys
import jax, jax.numpy as jnp
from experiments.pipeline import jax_cache
hits = []
jax.monitoring.register_event_listener(
  lambda name, **kw: hits.append(name) if name.endswith('cache_hits') else None
)
where = jax_cache.enable(sys.argv[1], min_compile_seconds=0.0)
f = jax.jit(lambda x: jnp.sin(x) @ jnp.cos(x).T + jnp.linalg.norm(x))
f(jnp.ones((8, 8))).block_until_ready()
print(json.dumps({'dir': where, 'hits': len(hits)}))
"""


def _child(path):
  out = subprocess.run(
    [sys.executable, '-c', _CHILD, path], cwd=ROOT, capture_output=True,
    text=True, check=True, timeout=300,
  )  # fmt: skip
  return json.loads(out.stdout.strip().splitlines()[-1])


def _files(path):
  return sorted(os.path.join(r, f) for r, _, fs in os.walk(path) for f in fs)


def test_a_second_process_loads_the_first_ones_program(tmp_path):
  cache = str(tmp_path / 'cache')
  first = _child(cache)
  assert first == {'dir': cache, 'hits': 0}
  written = _files(cache)
  assert written  # the program's entry
  second = _child(cache)
  assert second['hits'] >= 1
  assert _files(cache) == written  # nothing new compiled


def test_where_the_cache_goes(tmp_path, monkeypatch):
  monkeypatch.delenv(jax_cache.ENV, raising=False)
  monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path / 'xdg'))
  if jax.config.jax_compilation_cache_dir is None:
    assert jax_cache.resolve() == str(tmp_path / 'xdg' / 'physnet-jax' / 'jax')
  monkeypatch.setenv(jax_cache.ENV, str(tmp_path / 'env'))
  assert jax_cache.resolve() == str(tmp_path / 'env')
  assert jax_cache.resolve(str(tmp_path / 'arg')) == str(tmp_path / 'arg')
  monkeypatch.setenv(jax_cache.ENV, 'off')
  assert jax_cache.resolve() is None
  assert jax_cache.enable() is None
  assert jax_cache.resolve('OFF') is None

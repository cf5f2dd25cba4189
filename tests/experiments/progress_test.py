"""Tests for the progress bars: a terminal gets tqdm's live bar, a log file or
pipe a plain line every few percent with the rate and the time left (and the
compiling first batch left out of the rate); model.fit's bar the same."""

from __future__ import annotations

import contextlib
import io
import os
import re
import tempfile

import numpy as np
import pytest

import model
from experiments.pipeline import progress
from model import progress as model_progress

_RATE = re.compile(r'\d[\d.,]* \w+/s\b|\d[\d.]* s/\w+')
_LEFT = re.compile(r'\d+:\d\d left')


class _Terminal(io.StringIO):
  """A stream that says it is a terminal."""

  def isatty(self) -> bool:
    return True


def _lines(text: str) -> list[str]:
  return [line for line in text.split('\n') if line]


def test_a_log_gets_a_line_every_few_percent_with_rate_and_time_left():
  out = io.StringIO()
  with progress.Bar(1000, 'simulate', 'seq', file=out) as bar:
    for _ in range(1000):
      bar.done(1)
  text = out.getvalue()
  assert '\r' not in text and '\x1b' not in text
  lines = _lines(text)
  assert 20 <= len(lines) <= 25  # the first batch, every 5%, the end
  first, later = lines[0], lines[1:]
  assert first.startswith('simulate: 1/1000 (0%)') and 'compile' in first
  assert not _RATE.search(first)  # the compiling batch gives no rate
  for line in later:
    assert line.startswith('simulate: ')
    assert _RATE.search(line), line
    assert _LEFT.search(line), line
  assert later[0].startswith('simulate: 50/1000 (5%)')
  assert lines[-1].startswith('simulate: 1000/1000 (100%)')
  counts = [int(re.match(r'simulate: (\d+)/', line)[1]) for line in lines]
  assert counts == sorted(counts)


def test_a_log_file_on_disk_has_no_carriage_returns():
  with tempfile.TemporaryDirectory() as tmp:
    path = os.path.join(tmp, 'job.log')
    with open(path, 'w') as f, progress.Bar(1000, 'render', file=f) as bar:
      for _ in range(250):
        bar.done(4)
    with open(path, newline='') as f:
      text = f.read()
  assert '\r' not in text
  assert len(_lines(text)) <= 25
  assert _lines(text)[-1].startswith('render: 1000/1000 (100%)')


def test_the_rate_leaves_out_the_compiling_batch_and_skipped_items(monkeypatch):
  clock = iter(np.arange(0.0, 1000.0, 1.0))  # every reading one second later
  # one module: both bars read this clock
  assert model_progress.time is progress.time
  monkeypatch.setattr(progress.time, 'perf_counter', lambda: float(next(clock)))
  out = io.StringIO()
  bar = progress.Bar(100, 'sims', 'sim', file=out, every=0.5)
  bar.skip(40)  # found done: not timed
  bar.done(10)  # compiles
  bar.done(10)
  bar.close()
  lines = _lines(out.getvalue())
  assert lines[0].startswith('sims: 40/100 (40%)') and not _RATE.search(lines[0])
  assert lines[1].startswith('sims: 50/100 (50%)') and 'first batch' in lines[1]
  # 10 sims timed since the clock restarted after the compiling batch, over a
  # few (fake) seconds: a rate of a few sims/s, never 60 sims over the whole run
  last = lines[-1]
  assert last.startswith('sims: 60/100 (60%)')
  rate = float(re.search(r'([\d.]+) sim/s', last)[1])
  assert 1.0 <= rate <= 10.0
  assert bar.compile_seconds is not None


def test_a_terminal_gets_the_live_bar():
  out = _Terminal()
  with progress.Bar(100, 'simulate', 'seq', file=out) as bar:
    for _ in range(100):
      bar.done(1)
  text = out.getvalue()
  assert '\r' in text  # redrawn in place
  assert 'simulate' in text and '100/100' in text


def test_a_disabled_bar_writes_nothing():
  out = io.StringIO()
  with progress.Bar(10, 'x', file=out, disable=True) as bar:
    bar.done(10)
  assert out.getvalue() == ''


@pytest.mark.parametrize('stream', [io.StringIO(), _Terminal()])
def test_model_bar_is_tqdm_on_a_terminal_and_lines_elsewhere(stream):
  with model_progress.bar(200, 'fit', initial=20, file=stream) as bar:
    for _ in range(180):
      bar.update(1)
      bar.set_postfix(loss='0.1234')
  text = stream.getvalue()
  if stream.isatty():
    assert '\r' in text
  else:
    assert '\r' not in text
    lines = _lines(text)
    assert len(lines) <= 25
    assert lines[0].startswith('fit: 21/200')  # resumed at 20: the first update
    assert lines[-1].startswith('fit: 200/200 (100%)') and 'loss=0.1234' in lines[-1]
    assert all(_RATE.search(line) and _LEFT.search(line) for line in lines[1:])


def test_a_bar_without_a_total_writes_at_most_once_a_minute():
  out = io.StringIO()
  with model_progress.bar(None, 'read', file=out) as bar:
    for _ in range(1000):
      bar.update(1)
  lines = _lines(out.getvalue())
  assert lines[0].startswith('read: 1 it') and lines[-1].startswith('read: 1000 it')
  assert len(lines) == 2


def test_model_fit_logs_plain_lines_to_a_non_terminal_stderr():
  rng = np.random.default_rng(0)
  labels = np.repeat(np.arange(4), 6)
  images = rng.normal(size=(len(labels), 16, 16, 1)).astype(np.float32)
  config = model.TrainConfig(
    physnet=model.PhySNetConfig(
      image_size=(16, 16), conv_features=(2,), dense_features=(4,)
    ),
    batch_size=4, epochs=2, split='simulation', test_fraction=0.25, log_every=2,
    eval_triplets=50,
  )  # fmt: skip
  err = io.StringIO()
  with tempfile.TemporaryDirectory() as wd, contextlib.redirect_stderr(err):
    model.fit(images, labels, labels, config, wd, progress=True)
  fit_lines = [line for line in _lines(err.getvalue()) if line.startswith('fit: ')]
  assert '\r' not in err.getvalue()
  assert fit_lines and re.match(r'fit: (\d+)/\1 \(100%\)', fit_lines[-1])
  assert len(fit_lines) <= 25

"""Tests for physsim.input_files: regular files only, YAML without aliases
or deep nesting, long values shown briefly."""

from __future__ import annotations

import os
import socket
import time

import pytest

from physsim import input_files


def test_only_regular_files_pass_by_name(tmp_path):
  (tmp_path / 'ok.json').write_text('{}')
  input_files.check_regular(str(tmp_path / 'ok.json'))
  os.mkfifo(tmp_path / 'fifo.png')
  sock = socket.socket(socket.AF_UNIX)
  sock.bind(str(tmp_path / 's.json'))
  try:
    for name, kind in (('fifo.png', 'FIFO'), ('s.json', 'socket'), ('', 'folder')):
      path = str(tmp_path / name)
      with pytest.raises(ValueError, match=rf'is a {kind}.*not a regular frame'):
        input_files.check_regular(path, 'frame')
    with pytest.raises(ValueError, match=r'is a character device'):
      input_files.check_regular('/dev/null')
    with pytest.raises(ValueError, match=r'nowhere: no such camera file'):
      input_files.check_regular(str(tmp_path / 'nowhere'), 'camera file')
    assert input_files.is_special(str(tmp_path / 'fifo.png'))
    assert not input_files.is_special(str(tmp_path))
    assert not input_files.is_special(str(tmp_path / 'ok.json'))
  finally:
    sock.close()


@pytest.mark.parametrize(
  'text',
  ['a: &x [1, 2]\nb: *x\n', 'a: &x {k: 1}\nb:\n  <<: *x\n',
   '[' * 5000 + ']' * 5000, 'a:\n' + '- ' * 20_000 + '1',
   '{"a": ' * 3000 + '1' + '}' * 3000],
)  # fmt: skip
def test_yaml_aliases_and_deep_nesting_are_refused_at_once(text):
  t0 = time.perf_counter()
  with pytest.raises(ValueError, match=r'^f.yaml: (YAML aliases|not readable YAML)'):
    input_files.load_yaml(text, 'f.yaml')
  assert time.perf_counter() - t0 < 0.5


def test_plain_yaml_reads_and_values_are_shown_briefly():
  assert input_files.load_yaml('a: [1, {b: c}]\n', 'f.yaml') == {'a': [1, {'b': 'c'}]}
  assert input_files.shown('abc') == "'abc'"
  assert input_files.shown('x' * 1000) == 'a str of 1000 characters'
  assert input_files.shown(list(range(100))) == 'a list of 100 items'
  assert input_files.shown(10**400) == 'a int (401 characters)'

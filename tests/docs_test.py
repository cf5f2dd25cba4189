"""Tests for the documentation as a map: BENCHMARKS.md and every guide short,
every cited result and every relative link present, docs/README.md listing every
guide and docs/studies/README.md every study record, a record's links to files
that left the tree found in git at the commit named, and benchmarks/results
holding only small summaries. Reads files only (no JAX)."""

from __future__ import annotations

import glob
import os
import re
import subprocess

import pytest

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_RESULTS = 'benchmarks/results'
_MAX_LINES = 200  # BENCHMARKS.md: the current numbers, not a history
_MAX_GUIDE = 200  # a guide in docs/ (not a study record under docs/studies/)
_REMOVED_AFTER = 'c465b0e'  # where the records' removed benchmarks and results are
_MAX_FILE = 100 * 1024  # one committed summary
_MAX_TOTAL = 2 * 1024 * 1024  # every committed summary together
_LINK = re.compile(r'\[[^\]]*\]\(([^)\s]+)\)')
_CITED = re.compile(r'benchmarks/results/[A-Za-z0-9_.*/-]*')


def _pages() -> list[str]:
  """README.md, BENCHMARKS.md and every docs/*.md, relative to the root."""
  docs = sorted(glob.glob(os.path.join(_ROOT, 'docs', '*.md')))
  return ['README.md', 'BENCHMARKS.md', *(os.path.relpath(p, _ROOT) for p in docs)]


def _studies() -> list[str]:
  """Every dated study record, docs/studies/*.md, relative to the root."""
  found = sorted(glob.glob(os.path.join(_ROOT, 'docs', 'studies', '*.md')))
  return [os.path.relpath(p, _ROOT) for p in found]


def _read(page: str) -> str:
  with open(os.path.join(_ROOT, page), encoding='utf-8') as f:
    return f.read()


def _cited() -> dict[str, list[str]]:
  """Each path under benchmarks/results a page names -> the pages naming it."""
  out: dict[str, list[str]] = {}
  for page in _pages():
    for m in _CITED.finditer(_read(page)):
      path = m.group(0).rstrip('./')
      if path != _RESULTS:
        out.setdefault(path, []).append(page)
  return out


def _exists(path: str) -> bool:
  full = os.path.join(_ROOT, path)
  return bool(glob.glob(full)) if '*' in path else os.path.exists(full)


def _git(*args: str) -> subprocess.CompletedProcess:
  return subprocess.run(
    ['git', *args], cwd=_ROOT, capture_output=True, text=True, timeout=60
  )


def _git_checkout() -> bool:
  try:
    proc = _git('rev-parse', '--show-toplevel')
  except (OSError, subprocess.SubprocessError):
    return False
  # The project's own checkout, not a copy inside another repository.
  top = proc.stdout.strip()
  return proc.returncode == 0 and os.path.realpath(top) == os.path.realpath(_ROOT)


def test_benchmarks_is_short():
  lines = _read('BENCHMARKS.md').splitlines()
  assert len(lines) <= _MAX_LINES, f'BENCHMARKS.md has {len(lines)} lines'


def test_every_cited_result_exists():
  cited = _cited()
  assert cited, 'no page cites benchmarks/results: the pattern is wrong'
  missing = {p: pages for p, pages in cited.items() if not _exists(p)}
  assert not missing, f'cited but absent: {missing}'


def test_cited_results_are_not_ignored():
  if not _git_checkout():
    pytest.skip('not a git checkout')
  paths = [p for p in _cited() if '*' not in p]
  proc = _git('check-ignore', *paths)
  assert proc.returncode == 1, f'cited but ignored by git: {proc.stdout.split()}'


def _tracked_sizes(folder: str) -> dict[str, int]:
  proc = _git('ls-files', '-z', '--', folder)
  assert proc.returncode == 0, proc.stderr
  sizes = {}
  for path in filter(None, proc.stdout.split('\0')):
    full = os.path.join(_ROOT, path)
    if os.path.isfile(full):  # a file deleted but not yet committed is gone
      sizes[path] = os.path.getsize(full)
  return sizes


def test_committed_results_are_small():
  if not _git_checkout():
    pytest.skip('not a git checkout')
  sizes = _tracked_sizes(_RESULTS)
  big = {p: s for p, s in sizes.items() if s > _MAX_FILE}
  assert not big, f'over {_MAX_FILE} bytes: {big}'
  total = sum(sizes.values())
  assert total <= _MAX_TOTAL, f'{total} bytes in {_RESULTS}, over {_MAX_TOTAL}'


def test_committed_figures_are_small():
  if not _git_checkout():
    pytest.skip('not a git checkout')
  big = {p: s for p, s in _tracked_sizes('docs/figures').items() if s > _MAX_FILE}
  assert not big, f'over {_MAX_FILE} bytes (re-encode or drop): {big}'


def test_every_guide_is_short():
  long = {}
  for page in _pages():
    if page.startswith('docs' + os.sep):
      n = len(_read(page).splitlines())
      if n > _MAX_GUIDE:
        long[page] = n
  assert not long, (
    f'guides over {_MAX_GUIDE} lines (a record goes to docs/studies/): {long}'
  )


@pytest.mark.parametrize('index', ['docs/README.md', 'docs/studies/README.md'])
def test_a_docs_readme_lists_every_page_beside_it(index):
  listed = {os.path.normpath(t.split('#')[0]) for t in _LINK.findall(_read(index))}
  folder = os.path.dirname(index)
  pages = [os.path.basename(p) for p in _pages() + _studies()]
  pages = [p for p in pages if os.path.exists(os.path.join(_ROOT, folder, p))]
  missing = [p for p in pages if p != 'README.md' and p not in listed]
  assert not missing, f'{index} does not list {missing}'


def _relative_links(page: str):
  """(the link as written, the path it names relative to the root) per link."""
  base = os.path.dirname(os.path.join(_ROOT, page))
  for target in _LINK.findall(_read(page)):
    if re.match(r'[a-z][a-z0-9+.-]*:', target) or target.startswith('#'):
      continue  # a URL, or an anchor on the same page
    path = os.path.normpath(os.path.join(base, target.split('#')[0].split('?')[0]))
    yield target, os.path.relpath(path, _ROOT)


def test_relative_links_resolve():
  broken = []
  for page in _pages():
    for target, path in _relative_links(page):
      if not os.path.exists(os.path.join(_ROOT, path)):
        broken.append(f'{page}: {target}')
  assert not broken, 'links to missing files:\n' + '\n'.join(broken)


def test_a_records_links_resolve_here_or_in_git_where_it_says():
  # A study record is kept whole; what it links to under benchmarks/ may have
  # left the tree since, and must then be in git at the commit its README names.
  gone, broken = [], []
  for page in _studies():
    for _, path in _relative_links(page):
      if os.path.exists(os.path.join(_ROOT, path)):
        continue
      (gone if path.startswith('benchmarks' + os.sep) else broken).append((page, path))
  assert not broken, f'links to missing files: {broken}'
  if gone and not _git_checkout():
    pytest.skip('not a git checkout')
  proc = _git('ls-tree', '-r', '-t', '--name-only', _REMOVED_AFTER, '--', 'benchmarks')
  assert proc.returncode == 0, proc.stderr
  there = set(proc.stdout.split('\n'))
  absent = [
    (page, path) for page, path in gone if path.replace(os.sep, '/') not in there
  ]
  assert not absent, f'gone from the tree and not at {_REMOVED_AFTER}: {absent}'

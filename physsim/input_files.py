"""Guards for the files a user hands in: regular files only, YAML without
aliases, values shown briefly in errors.

``open()`` on a FIFO named like a frame (``0006.png``) waits for a writer
that never comes, and a device may never end: such names are refused by
``check_regular`` from ``os.stat`` alone, before anything opens them. A YAML
alias bomb (a few hundred bytes whose anchors expand to gigabytes) is refused
at its first alias by ``load_yaml``; no file this project reads needs one.
"""

from __future__ import annotations

import os
import re
import stat

# Longest repr of a value quoted in an error line; longer ones are described.
MAX_SHOWN = 60
# The deepest YAML nesting read (no file of ours nests over ten): deeper is
# refused as it is met, before the recursion and time a deep one costs.
MAX_DEPTH = 100


def kind(mode: int) -> str:
  """What a ``st_mode`` names, in words ('a FIFO', 'a folder', ...)."""
  for test, words in (
    (stat.S_ISREG, 'a regular file'),
    (stat.S_ISDIR, 'a folder'),
    (stat.S_ISFIFO, 'a FIFO (named pipe)'),
    (stat.S_ISSOCK, 'a socket'),
    (stat.S_ISCHR, 'a character device'),
    (stat.S_ISBLK, 'a block device'),
  ):
    if test(mode):
      return words
  return 'not a regular file'


def check_regular(path: str, what: str = 'file') -> None:
  """Refuses ``path`` unless it is a regular file (symlinks followed).

  Args:
    path: the file about to be opened.
    what: what it should be, for the message ('frame', 'camera file').

  Raises:
    ValueError: naming the path: missing, or a FIFO, socket, device or
      folder (a FIFO would block ``open()`` forever).
  """
  try:
    mode = os.stat(path).st_mode
  except FileNotFoundError:
    raise ValueError(f'{path}: no such {what}') from None
  except OSError as e:
    raise ValueError(f'{path}: cannot be read ({e.strerror})') from None
  if not stat.S_ISREG(mode):
    raise ValueError(f'{path}: is {kind(mode)}, not a regular {what}')


def is_special(path: str) -> bool:
  """True where ``path`` exists and is neither a regular file nor a folder."""
  try:
    mode = os.stat(path).st_mode
  except OSError:
    return False
  return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def read_text(path: str, what: str, max_bytes: int) -> str:
  """A regular UTF-8 text file of at most ``max_bytes``.

  Raises:
    ValueError: naming the path: not a regular file, too large, unreadable
      or not UTF-8.
  """
  check_regular(path, what)
  size = os.path.getsize(path)
  if size > max_bytes:
    raise ValueError(
      f'{path}: {size} bytes is too large for a {what} (at most {max_bytes})'
    )
  try:
    with open(path, encoding='utf-8') as f:
      return f.read(max_bytes + 1)
  except UnicodeDecodeError as e:
    raise ValueError(
      f'{path}: not a text file ({e.reason} at byte {e.start})'
    ) from None
  except OSError as e:
    raise ValueError(f'{path}: cannot be read ({e.strerror})') from None


def load_yaml(text: str, path: str):
  """YAML ``text`` read safely (``yaml.SafeLoader``), refusing any alias.

  Raises:
    ValueError: naming ``path``: an alias (``*name``), unreadable YAML or
      nesting over ``MAX_DEPTH``; one line.
  """
  import yaml  # noqa: PLC0415 - only YAML files need it

  class _NoAliases(yaml.SafeLoader):
    depth = 0

    def compose_node(self, parent, index):
      if self.check_event(yaml.AliasEvent):
        event = self.peek_event()
        line = event.start_mark.line + 1 if event.start_mark else 0
        raise ValueError(
          f'{path}: YAML aliases (*{shown(event.anchor)}, line {line}) are not '
          'accepted; write the values out'
        )
      self.depth += 1
      if self.depth > MAX_DEPTH:
        raise ValueError(f'{path}: not readable YAML (nested over {MAX_DEPTH} deep)')
      try:
        return super().compose_node(parent, index)
      finally:
        self.depth -= 1

  # PyYAML's scanner takes time quadratic in the depth of flow collections
  # ([[[...]]]): refused from the brackets alone (in a string they would
  # rarely nest a hundred deep).
  depth = 0
  for c in re.findall(r'[\[\]{}]', text):
    depth += 1 if c in '[{' else -1
    if depth > MAX_DEPTH:
      raise ValueError(f'{path}: not readable YAML (nested over {MAX_DEPTH} deep)')
  try:
    return yaml.load(text, Loader=_NoAliases)  # noqa: S506 - a SafeLoader
  except yaml.YAMLError as e:
    raise ValueError(f'{path}: not readable YAML ({short(e)})') from None
  except RecursionError:
    raise ValueError(f'{path}: not readable YAML (nested too deeply)') from None


def shown(value, limit: int = MAX_SHOWN) -> str:
  """``repr(value)`` when short, else its type and size ('a list of 10000
  items'), so that an error line stays one short line."""
  if isinstance(value, str | bytes | list | tuple | dict | set):
    if len(value) > limit:
      unit = 'characters' if isinstance(value, str) else 'items'
      unit = 'bytes' if isinstance(value, bytes) else unit
      return f'a {type(value).__name__} of {len(value)} {unit}'
  text = repr(value)
  return (
    text if len(text) <= limit else f'a {type(value).__name__} ({len(text)} characters)'
  )


def short(e: BaseException, limit: int = 200) -> str:
  """An exception's message on one line, cut to ``limit`` characters."""
  text = ' '.join(str(e).split())
  return text if len(text) <= limit else text[: limit - 3] + '...'

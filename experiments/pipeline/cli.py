"""Command lines from config dataclasses: the one config mechanism of the scripts.

A script declares one frozen dataclass whose fields are its settings, each
documented under ``Attributes:`` in the class docstring (meaning, units). A
field that is itself a dataclass (a library's config, e.g. ``EstimateConfig``)
contributes its own fields as flags under their own names, so a library config
is never copied field by field. ``--preset`` picks a named instance of the
script's dataclass; flags given on the command line override it.

  @dataclasses.dataclass(frozen=True)
  class Args:
    \"\"\"...
    Attributes:
      workdir: where results go.
      search: the search settings.
    \"\"\"
    workdir: str = cli.required()
    search: EstimateConfig = EstimateConfig()

  if __name__ == '__main__':
    cli.run(Args, {'default': Args(), 'smoke': Args(search=SMOKE)}, main)

User errors (``ValueError``, ``OSError``, a flag that does not parse, a
numeric setting that is NaN or infinite) end the run with one line on stderr
and exit status 2; ``--verbose`` shows the traceback instead. Ctrl-C ends it
with one line that gives the command that resumes it (exit status 130), as
does SIGTERM (a batch system's time limit), and so
does a job's ``--time_limit`` between two of its steps (exit status 75:
``deadline``).
"""

from __future__ import annotations

import dataclasses
import inspect
import logging
import math
import os
import re
import shlex
import signal
import sys
import types
import typing
from collections.abc import Callable, Collection, Mapping

from absl import app, flags

from experiments.pipeline import deadline

_REQUIRED = 'required'
_CHOICES = 'choices'
_SKIP = 'skip'
_FLAG = 'flag'
_ALIASES = 'aliases'


def required(default: str = ''):
  """A string field the command line must give (``--name=...``)."""
  return dataclasses.field(default=default, metadata={_REQUIRED: True})


def choice(default: str, choices):
  """A string field restricted to ``choices`` (an enum flag)."""
  return dataclasses.field(default=default, metadata={_CHOICES: tuple(choices)})


def renamed(default, flag: str, *, aliases: tuple[str, ...] = ()):
  """A field whose flag has another name than the field (``--flag``): where a
  script's word for a setting differs from the library's. ``aliases``: older
  names the flag still answers to (deprecated; ``--help`` says which)."""
  return dataclasses.field(default=default, metadata={_FLAG: flag, _ALIASES: aliases})


def nested(default, *, skip=()):
  """A field holding a library's config whose fields become flags, except
  those named in ``skip`` (set by the library from other settings; a dotted
  name skips a field of a config nested deeper, e.g. ``'fit.split'``)."""
  return dataclasses.field(default=default, metadata={_SKIP: tuple(skip)})


def field_docs(cls) -> dict[str, str]:
  """Each field's text from the ``Attributes:`` section of ``cls``'s docstring.

  A line ``name: text`` (or ``a, b: text`` for fields described together)
  starts an entry; more deeply indented lines continue it.
  """
  doc = inspect.cleandoc(cls.__doc__ or '')
  lines = doc.splitlines()
  try:
    start = next(i for i, line in enumerate(lines) if line.strip() == 'Attributes:')
  except StopIteration:
    return {}
  out: dict[str, str] = {}
  current: list[str] = []
  indent = None
  for line in lines[start + 1 :]:
    if not line.strip():
      continue
    depth = len(line) - len(line.lstrip())
    if depth == 0:
      break
    indent = depth if indent is None else indent
    m = re.match(r'^([A-Za-z_][\w, ]*):\s*(.*)$', line.strip())
    if depth == indent and m:
      current = [n.strip() for n in m.group(1).split(',')]
      for n in current:
        out[n] = m.group(2)
    elif current:
      for n in current:
        out[n] += ' ' + line.strip()
  return out


class _Leaf(typing.NamedTuple):
  path: tuple[str, ...]  # field names from the script's dataclass down
  field: dataclasses.Field
  type: object
  doc: str

  @property
  def flag(self) -> str:
    return self.field.metadata.get(_FLAG, self.path[-1])


def _is_config(t) -> bool:
  return isinstance(t, type) and dataclasses.is_dataclass(t)


def leaves(cls) -> list[_Leaf]:
  """The flag-carrying fields of ``cls``, nested dataclasses flattened.

  Raises:
    ValueError: two fields would take the same flag name, or a field has no
      ``Attributes:`` entry or a type flags cannot carry.
  """
  out: list[_Leaf] = []

  def walk(c, path, skip=()):
    hints = typing.get_type_hints(c)
    docs = field_docs(c)
    for f in dataclasses.fields(c):
      if f.name in skip:
        continue
      t = hints[f.name]
      if _is_config(t):
        deeper = tuple(s[len(f.name) + 1 :] for s in skip if s.startswith(f.name + '.'))
        walk(t, path + (f.name,), f.metadata.get(_SKIP, ()) + deeper)
        continue
      if f.name not in docs:
        raise ValueError(f'{c.__name__}.{f.name} has no Attributes: entry')
      _parser(t, f'{c.__name__}.{f.name}')  # checks the type
      out.append(_Leaf(path + (f.name,), f, t, docs[f.name]))

  walk(cls, ())
  names = [leaf.flag for leaf in out]
  dup = sorted({n for n in names if names.count(n) > 1})
  if dup:
    raise ValueError(f'{cls.__name__}: flag names {dup} appear in more than one config')
  return out


def _parser(t, where: str):
  """``(kind, element type)`` of a field type, kind in bool/int/float/str/list."""
  origin = typing.get_origin(t)
  if t in (bool, int, float, str):
    return t.__name__, t
  if origin is tuple:
    args = typing.get_args(t)
    if len(args) == 2 and args[1] is Ellipsis and args[0] in (str, int, float):
      return 'list', args[0]
  if origin in (typing.Union, types.UnionType):
    raise ValueError(f'{where}: optional types cannot be flags; use a default')
  raise ValueError(f'{where}: type {t} cannot be a flag')


def _get(obj, path):
  for p in path:
    obj = getattr(obj, p)
  return obj


def _replace(obj, path, value):
  if len(path) == 1:
    return dataclasses.replace(obj, **{path[0]: value})
  child = _replace(getattr(obj, path[0]), path[1:], value)
  return dataclasses.replace(obj, **{path[0]: child})


# Where --help's further flags are listed (--helpfull shows them).
FURTHER = 'further flags'


def define_flags(
  cls,
  presets: Mapping[str, object],
  flag_values: flags.FlagValues = flags.FLAGS,
  module_name: str | None = None,
  key_flags: Collection[str] | None = None,
) -> None:
  """Defines ``--preset``, ``--verbose`` and one flag per leaf field of ``cls``.

  Help text is the field's documentation; the default shown is the first
  preset's value. ``module_name`` is the module ``--help`` lists them under
  (the running script's: absl names it by ``sys.argv[0]``). ``key_flags``:
  the flags a person needs, the only ones ``--help`` lists; the others go
  under ``FURTHER``, which ``--helpfull`` lists with them. None: every flag
  is a key one.

  Raises:
    ValueError: no preset, or a key flag that is no flag of ``cls``.
  """
  if not presets:
    raise ValueError(f'{cls.__name__}: need at least one preset')
  first = next(iter(presets.values()))
  all_leaves = leaves(cls)
  if key_flags is not None:
    known = {leaf.flag for leaf in all_leaves} | {'preset', 'verbose', 'time_limit'}
    unknown = sorted(set(key_flags) - known)
    if unknown:
      raise ValueError(f'{cls.__name__}: key flags {unknown} are no flags of it')

  def kw(name: str) -> dict:
    key = key_flags is None or name in key_flags
    return dict(flag_values=flag_values, module_name=module_name if key else FURTHER)

  flags.DEFINE_enum(
    'preset', next(iter(presets)), list(presets),
    'named settings; flags given override them', **kw('preset'),
  )  # fmt: skip
  flags.DEFINE_bool('verbose', False, 'show the traceback of an error', **kw('verbose'))
  flags.DEFINE_float(
    'time_limit', 0.0,
    'seconds from the start after which no new step of a long job begins (it '
    'stops cleanly between steps, exit status 75, and resumes when run again); 0: none',
    **kw('time_limit'),
  )  # fmt: skip
  for leaf in all_leaves:
    name, doc = leaf.flag, leaf.doc
    default = _get(first, leaf.path)
    kind, elem = _parser(leaf.type, name)
    choices = leaf.field.metadata.get(_CHOICES)
    where = kw(name)
    if choices:
      flags.DEFINE_enum(name, default, list(choices), doc, **where)
    elif kind == 'bool':
      flags.DEFINE_bool(name, default, doc, **where)
    elif kind == 'int':
      flags.DEFINE_integer(name, default, doc, **where)
    elif kind == 'float':
      flags.DEFINE_float(name, default, doc, **where)
    elif kind == 'str':
      flags.DEFINE_string(name, default, doc, **where)
    else:
      flags.DEFINE_list(name, [str(v) for v in default], doc, **where)
    for alias in leaf.field.metadata.get(_ALIASES, ()):
      flags.DEFINE_alias(alias, name, **where)


def from_flags(
  cls, presets: Mapping[str, object], flag_values: flags.FlagValues = flags.FLAGS
):
  """The chosen preset with the flags given on the command line applied.

  Raises:
    ValueError: a required field is missing, given empty (``--workdir=``)
      as is one whose default is not, or a list holds a bad value.
  """
  config = presets[flag_values.preset]
  missing = []
  for leaf in leaves(cls):
    name = leaf.flag
    flag = flag_values[name]
    if flag.present:
      value = flag.value
      kind, elem = _parser(leaf.type, name)
      if kind == 'int':
        check_count(name, value)
      if kind == 'str' and not value.strip():
        # '--workdir=' (a shell variable that was never set): refused by name,
        # where the field wants a value or has one by default.
        if leaf.field.metadata.get(_REQUIRED) or _get(config, leaf.path):
          raise ValueError(f'--{name}: empty')
      if kind == 'list':
        try:
          value = tuple(elem(v) for v in value)
        except ValueError as e:
          raise ValueError(f'--{name}: {e}') from e
      config = _replace(config, leaf.path, value)
    if leaf.field.metadata.get(_REQUIRED) and not _get(config, leaf.path):
      missing.append(f'--{name}')
  if missing:
    raise ValueError(f'missing {", ".join(missing)} (see --help)')
  check_numbers(config)
  return config


def _flag_name(f: dataclasses.Field) -> str:
  return f.metadata.get(_FLAG, f.name)


# Every count and size an int flag gives on the command line is bounded here,
# before any script allocates by it (a library's own check may bound it
# tighter): these flags by name, any other int flag (seeds aside) to
# [0, MAX_COUNT].
MAX_COUNT = 10**7
INT_LIMITS = {
  'frames': (1, 10_000), 'cameras': (1, 64), 'image_size': (0, 8192),
  'shape_image_size': (0, 8192), 'resolution': (0, 8192),
  'cloth_resolution': (2, 1024), 'batch_size': (1, 1 << 16),
  'eval_batch_size': (1, 1 << 16), 'q': (1, 100_000), 'n_init': (1, 100_000),
  'workers': (0, 4096), 'processes': (1, 4096), 'gpus_per_process': (0, 64),
  'port': (1, 65535), 'nodes': (1, 1000), 'draws': (0, 1_000_000),
}  # fmt: skip


def check_count(name: str, value: int) -> None:
  """Refuses an int flag's value outside its bounds (``INT_LIMITS``), seeds
  aside (any 64-bit value).

  Raises:
    ValueError: ``--name=value: need lo to hi``.
  """
  if 'seed' in name:
    return
  lo, hi = INT_LIMITS.get(name, (0, MAX_COUNT))
  if not lo <= value <= hi:
    shown = str(value) if len(str(value)) <= 24 else f'{str(value)[:20]}...'
    raise ValueError(f'--{name}={shown}: need {lo} to {hi}')


# The largest int a flag may hold (64-bit signed).
MAX_INT = 2**63 - 1


def check_numbers(config) -> None:
  """One check for every numeric field of a config and the configs nested in
  it: each float (or element of a tuple of them) must be finite, each int
  within 64 bits (no count or size is larger; a longer one is a typo).

  Raises:
    ValueError: ``--flag=value: ...`` naming the first field that is NaN,
      infinite, too large (or not a number at all).
  """
  for f in dataclasses.fields(config):
    value = getattr(config, f.name)
    if dataclasses.is_dataclass(value):
      check_numbers(value)
      continue
    items = value if isinstance(value, tuple) else (value,)
    for v in items:
      if isinstance(v, bool | str) or v is None:
        continue
      if isinstance(v, int) and not -MAX_INT <= v <= MAX_INT:
        raise ValueError(
          f'--{_flag_name(f)}={str(v)[:20]}...: {len(str(v))} digits, too large '
          f'(at most {MAX_INT})'
        )
      try:
        finite = math.isfinite(v)
      except (TypeError, OverflowError):
        finite = False
      if not finite:
        shown = ','.join(map(str, items)) if isinstance(value, tuple) else str(v)
        raise ValueError(
          f'--{_flag_name(f)}={shown}: every number must be finite (not NaN or inf)'
        )


def parse(cls, presets: Mapping[str, object], argv: list[str]):
  """``from_flags`` for a command line ``argv`` (program name first), on a
  fresh set of flags: for tests and for calling a script from Python."""
  fv = flags.FlagValues()
  define_flags(cls, presets, fv)
  fv(argv)
  return from_flags(cls, presets, fv)


def host_devices(n: int | None = None) -> None:
  """Asks XLA for ``n`` CPU devices (default: one fewer than the cores, at
  least one) unless the environment already says how many, so that
  independent host work (one GP per recording in a lockstep estimate) runs in
  parallel: one CPU device runs its programs one at a time.

  Not one per core: jaxlib's batched LAPACK kernels (a GP's Cholesky over a
  batch of candidates) wait inside XLA's intra-op thread pool, one thread per
  core, for work they put on that same pool; with a device per core every
  pool thread can be such a waiter and none is left to do the work, a
  deadlock (a lockstep estimate at the default size hung at its first GP step
  on two cores). One thread more than devices keeps one free. Takes effect
  only before JAX starts its backends."""
  flags_ = os.environ.get('XLA_FLAGS', '')
  if 'xla_force_host_platform_device_count' in flags_:
    return
  n = n or max(1, (os.cpu_count() or 1) - 1)
  os.environ['XLA_FLAGS'] = (
    f'{flags_} --xla_force_host_platform_device_count={n}'.strip()
  )


# The longest error line printed; a longer one is cut (a flag's or file's long
# value echoed back), its head naming the flag or file.
MAX_LINE = 300


def one_line(e: BaseException) -> str:
  """A user error's message on one line (the lines of a longer one joined),
  at most ``MAX_LINE`` characters."""
  text = '; '.join(line.strip() for line in str(e).splitlines() if line.strip())
  if len(text) <= MAX_LINE:
    return text
  cut = f'... ({len(text)} characters)'
  return text[: MAX_LINE - len(cut)] + cut


def resume_command(argv: list[str] | None = None) -> str:
  """The command line that ran this script (``python -m module ...``), quoted
  for a shell: what resumes it after an interruption."""
  argv = list(sys.argv if argv is None else argv)
  spec = getattr(sys.modules.get('__main__'), '__spec__', None)
  head = ['python', '-m', spec.name] if spec and spec.name else ['python', argv[0]]
  return shlex.join(head + argv[1:])


def _parse_flags(argv):
  """absl's flag parsing, its errors as one line and exit status 2."""
  try:
    return flags.FLAGS(argv)
  except flags.Error as e:
    print(f'error: {one_line(e)} (see --help)', file=sys.stderr)
    sys.exit(2)


def run(
  cls,
  presets: Mapping[str, object],
  main: Callable[[object], object],
  *,
  key_flags: Collection[str] | None = None,
) -> None:
  """A script's whole ``__main__``: flags from ``cls``, ``main(config)``, and
  user errors as one line (exit status 2) unless ``--verbose``; Ctrl-C as one
  line naming the command that resumes (exit status 130). Under a
  multi-process launch (``distributed``) the processes are joined first.
  ``key_flags``: the flags ``--help`` lists (``define_flags``; the rest under
  ``--helpfull``)."""
  from experiments.pipeline import distributed, jax_cache  # noqa: PLC0415 - imports jax
  from physsim import interrupt  # noqa: PLC0415 - imports jax

  host_devices()
  # JAX's "Unable to initialize backend 'tpu'" (INFO, on every machine without
  # one) was the first line a newcomer read; its warnings and errors still show.
  logging.getLogger('jax._src.xla_bridge').setLevel(logging.WARNING)
  # SIGTERM (a batch system's time limit, a launcher stopping its processes,
  # whose SIGINT a background job ignores) ends the run as Ctrl-C does; both
  # wait for the simulator's callback to return (physsim.interrupt).
  interrupt.install((signal.SIGINT, signal.SIGTERM))
  jax_cache.enable()  # a later process loads what this one compiles
  distributed.initialize()
  define_flags(cls, presets, module_name=sys.argv[0], key_flags=key_flags)

  def _main(argv):
    try:
      if len(argv) > 1:
        raise ValueError(f'unexpected arguments {argv[1:]} (flags are --name=value)')
      deadline.set_limit(flags.FLAGS.time_limit, start=deadline.STARTED)
      main(from_flags(cls, presets))
    except deadline.Reached as e:
      print(f'{e}; resume with: {resume_command()}', file=sys.stderr)
      sys.exit(deadline.EXIT_STATUS)
    except (ValueError, OSError) as e:
      if flags.FLAGS.verbose:
        raise
      print(f'error: {one_line(e)} (--verbose shows the traceback)', file=sys.stderr)
      sys.exit(2)
    except KeyboardInterrupt:
      if flags.FLAGS.verbose:
        raise
      print(f'interrupted; resume with: {resume_command()}', file=sys.stderr)
      sys.exit(130)

  try:
    app.run(_main, flags_parser=_parse_flags)
  except KeyboardInterrupt:  # before main started (imports, flag parsing)
    print(f'interrupted; resume with: {resume_command()}', file=sys.stderr)
    sys.exit(130)
  except SystemExit as e:
    # absl ends --help with status 1; asking for help is no failure.
    if e.code == 1 and _HELP_FLAGS & set(sys.argv[1:]):
      sys.exit(0)
    raise


_HELP_FLAGS = {'--help', '-h', '-?', '--helpshort', '--helpfull'}

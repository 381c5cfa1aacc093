"""``axdf`` entry point: ``main(argv=None) -> int``; one module per subcommand.

Each subcommand module has ``add_args(parser)`` and ``run(args) -> int``. Errors raised below
the CLI become exit codes here: 2 bad input (``FILE:LINE:COL: what; allowed``), 3 the
environment cannot do the work, 130 interrupted. No traceback reaches the user unless
``--traceback`` is given.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import signal
import sys

from axdf_cli import __version__
from axdf_cli.errors import AxdfError, EnvironmentProblem, InputError, Interrupted, UsageError

# name -> (module, help). The order is the order of `axdf --help`.
COMMANDS = {
    "run": ("axdf_cli.cli.run", "evaluate muscles over a pose; write meshes, stats (and frames)"),
    "render": ("axdf_cli.cli.render", "render preview frames and EXR data passes from a finished run"),
    "validate": ("axdf_cli.cli.validate", "check muscle, skeleton, pose and job files; write nothing"),
    "compare": ("axdf_cli.cli.compare", "compare a run (or one file) with a golden one; exit 1 when different"),
    "import": ("axdf_cli.cli.importer", "import OpenSim models and motions, or BVH motion capture, as axdf files"),
    "transfer": ("axdf_cli.cli.transfer", "move muscles onto another skeleton through a bone map"),
    "pack": ("axdf_cli.cli.pack", "make a body's muscles share space at the rest pose (section outlines)"),
    "fit": ("axdf_cli.cli.fit", "fit closed muscle meshes (STL, PLY, OBJ) as AxDf muscle files"),
    "atlas": ("axdf_cli.cli.atlas", "register an anatomical atlas onto a skeleton and fit its muscles"),
    "retarget": ("axdf_cli.cli.retarget", "fit a muscle model's skeleton to motion capture (BVH, 3D joints)"),
    "dataset": ("axdf_cli.cli.dataset", "build data sets: sampled poses, several views, labels, one index"),
    "skin": ("axdf_cli.cli.skin", "fit a CC0 body (MakeHuman) to a skeleton at rest: a skin file"),
}


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own errors: exit 2 with the usage line
        self.print_usage(sys.stderr)
        sys.stderr.write(f"axdf: error: {message}\n")
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="axdf", description="AxDf muscle meshes from YAML muscles and poses.")
    p.add_argument("--version", action="version", version=f"axdf {__version__}")
    p.add_argument("--traceback", action="store_true", help=argparse.SUPPRESS)
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name, (modname, help_text) in COMMANDS.items():
        mod = importlib.import_module(modname)
        sp = sub.add_parser(name, help=help_text, description=(mod.__doc__ or help_text).strip().splitlines()[0])
        g = sp.add_mutually_exclusive_group()
        g.add_argument("-q", "--quiet", action="store_true", help="print only errors")
        g.add_argument("-v", "--verbose", action="store_true", help="print more detail")
        mod.add_args(sp)
        sp.set_defaults(_module=mod)
    return p


def main(argv: list[str] | None = None) -> int:
    """The command's exit code; an interrupt the signal handler recorded is 130 whatever the
    command did after it (a library that catches KeyboardInterrupt or BaseException cannot
    turn it into success or exit 70)."""
    from axdf_cli.fileio import atomic

    atomic.reset_interrupt()
    old = _install(atomic.on_signal)  # before anything heavy is imported
    hook = sys.unraisablehook
    if old:
        atomic.catch_interrupts_in_callbacks()  # a Ctrl-C while numba loads a kernel
    try:
        rc = _main(argv, atomic)
        if atomic.interrupted() and rc != 130:
            print("axdf: interrupted", file=sys.stderr)
            rc = 130
    finally:
        for sig, handler in old.items():  # (the entry point's own handlers: it keeps them until exit)
            signal.signal(sig, handler)
        sys.unraisablehook = hook
    return rc


def _install(handler) -> dict:
    """``handler`` for SIGINT and SIGTERM: the previous handlers by signal (none where this is
    not the main thread: tests calling main in a thread)."""
    old = {}
    for sig in (signal.SIGINT, signal.SIGTERM):  # both end the run with 130, never mid-file
        try:
            old[sig] = signal.signal(sig, handler)
        except ValueError:
            pass
    return old


#: Commands that run numba's kernels, and the actions of theirs that do (or a test of the
#: arguments: ``skin`` evaluates muscles only with ``--muscles``): a note before a cold compile
#: (runtime.compile_notice).
KERNEL_COMMANDS = {"run": None, "pack": None, "dataset": ("build",), "import": ("osim", "mjcf"), "fit": None,
                   "atlas": lambda args: not args.register_only, "skin": lambda args: args.muscles is not None}


def _notice(args) -> str | None:
    """The command's key in the kernel cache when it will compile numba's kernels, after
    printing the compile notice (unless --quiet) when they are not cached yet."""
    if args.command not in KERNEL_COMMANDS:
        return None
    actions = KERNEL_COMMANDS[args.command]
    if callable(actions):
        if not actions(args):
            return None
    elif actions is not None and getattr(args, "action", getattr(args, "source", None)) not in actions:
        return None
    from axdf_cli import runtime

    missing, total = runtime.cold_kernels(args.command)
    if missing and not args.quiet:
        print(runtime.compile_line(missing, total, os.environ.get("NUMBA_CACHE_DIR")), file=sys.stderr, flush=True)
        args.compiling = missing
    return args.command


def _main(argv, atomic) -> int:
    from axdf_cli import runtime

    runtime.configure()  # threads and numba's cache, before a subcommand imports numba or numpy
    args = None
    try:
        for a in sys.argv[1:] if argv is None else argv:
            if isinstance(a, str) and any("\udc80" <= c <= "\udcff" for c in a):  # bytes that are not UTF-8
                raise UsageError(f"argument {a.encode('utf-8', 'surrogateescape')!r} is not UTF-8 text",
                                 "file and folder names in UTF-8 (axdf writes names into its text files)")
        parser = build_parser()  # (imports every subcommand: a Ctrl-C here is "interrupted" too)
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:
            return int(e.code or 0) if not isinstance(e.code, str) else 2
        warm = _notice(args)
        progress = (runtime.compile_progress(lambda line: print(line, file=sys.stderr, flush=True))
                    if getattr(args, "compiling", 0) else contextlib.nullcontext())  # a cold cache: progress
        with progress:
            rc = int(args._module.run(args) or 0)
        if rc == 0 and warm and not atomic.interrupted():
            runtime.mark_warm(warm)
        return rc
    except InputError as e:
        if args is not None and args.traceback:
            raise
        print(f"axdf: {e}" if e.where is None else str(e), file=sys.stderr)
        return 2
    except EnvironmentProblem as e:
        if args is not None and args.traceback:
            raise
        print(f"axdf: {e.problem}", file=sys.stderr)
        if e.hint:
            print(f"hint: {e.hint}", file=sys.stderr)
        return 3
    except (KeyboardInterrupt, Interrupted):
        print("axdf: interrupted", file=sys.stderr)
        return 130
    except AxdfError as e:
        if args is not None and args.traceback:
            raise
        print(f"axdf: {e}", file=sys.stderr)
        return e.exit_code
    except MemoryError:
        print("axdf: out of memory; use fewer frames per run or a lower resolution", file=sys.stderr)
        return 3
    except Exception as e:  # a bug: say so plainly, without a traceback unless asked
        if atomic.interrupted():  # a library turned the interrupt into another exception
            print("axdf: interrupted", file=sys.stderr)
            return 130
        if args is not None and args.traceback:
            raise
        print(f"axdf: internal error: {type(e).__name__}: {e}\n"
              "rerun with --traceback and report it", file=sys.stderr)
        return 70


def _late(signum, frame) -> None:
    """SIGINT/SIGTERM once the command is over and its output flushed: exit 130 at once (the
    interpreter's teardown would otherwise die of the signal with no word)."""
    os.write(2, b"axdf: interrupted\n")
    os._exit(130)


def entry() -> None:
    """The ``axdf`` program: SIGINT and SIGTERM are handled from its first line to its exit,
    130 with "axdf: interrupted" at any moment (a signal inherited blocked is let through once
    the handlers are in place)."""
    from axdf_cli.fileio import atomic

    rc = None
    try:
        _install(atomic.on_signal)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
        rc = main()
    except KeyboardInterrupt:  # in the instants outside main's own handling
        rc = None
    _install(_late)  # from here on a signal ends the process at once
    if rc is None or (rc != 130 and atomic.interrupted()):
        _late(None, None)
    # The teardown is done here, under _late: the interpreter's own finalization puts the
    # default handlers back first, and a signal then (or one sent again by the unraisable hook's
    # timer) would kill the process with no word.
    import atexit

    atexit._run_exitfuncs()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except OSError:  # a closed pipe: the exit code still says how the command ended
        pass
    os._exit(rc)


if __name__ == "__main__":
    entry()

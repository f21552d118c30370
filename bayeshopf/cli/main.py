"""``bayeshopf`` console script: the dispatcher of the subcommands.

Each subcommand is one module of :mod:`bayeshopf.cli` with ``DESCRIPTION``,
``add_arguments(parser)`` and ``run(args) -> int``; this module lists them
(:data:`COMMANDS`), builds the parser, prepares the runtime and runs the one
asked for. A command's module, and with it JAX and the library, is imported
only when that command runs or its help is asked for, so ``bayeshopf --help``
imports neither.

Errors in the input or the output folder (:class:`~bayeshopf.errors.BayesHopfError`)
are reported as one line on stderr (which file, field or flag, what was expected,
what was found) with exit code 2 and no traceback; other errors as one line
with exit code 1, and their traceback with ``--debug``.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import sys
import traceback
from collections.abc import Iterable
from dataclasses import dataclass
from types import ModuleType

from bayeshopf import __version__
from bayeshopf.errors import BayesHopfError

EXIT_USAGE = 2
EXIT_ERROR = 1
EXIT_INTERRUPTED = 130
#: Equinox's mode for its run-time checks in the CLI's process (:func:`prepare_runtime`).
EQX_ON_ERROR = ("EQX_ON_ERROR", "nan")


@dataclass(frozen=True)
class Command:
    """A subcommand: the module that defines and runs it, and its one-line help."""

    module: str
    help: str


#: The subcommands, in the order ``bayeshopf --help`` lists them.
COMMANDS: dict[str, Command] = {
    "demo": Command("bayeshopf.cli.demo",
                    "fit simulated recordings of the 3-DOF aeroelastic aerofoil"),
    "fit": Command("bayeshopf.cli.fit", "fit recordings in a folder"),
    "predict": Command("bayeshopf.cli.predict", "amplitude and frequency at μ from a saved fit"),
    "download": Command("bayeshopf.cli.download", "download a published data set"),
    "plot": Command("bayeshopf.cli.plot",
                    "draw a saved fit's figures again, without refitting"),
    "simulate": Command("bayeshopf.cli.simulate",
                        "simulated LCO recordings of a known system (vanderpol, flutter3dof)"),
    "discrepancy": Command("bayeshopf.cli.discrepancy",
                           "locate and name the physics a simulator lacks"),
    "next": Command("bayeshopf.cli.design", "rank the next measurements by how much they "
                    "shrink the fold, Hopf or diagram intervals"),
    "report": Command("bayeshopf.cli.lab_report",
                      "one self-contained HTML page of a saved fit, to mail or archive"),
}


def prepare_runtime() -> None:
    """Threads, devices, compilation cache and float64, before the library loads.

    One OpenBLAS thread (NumPy's and SciPy's, whose busy-waiting workers would
    otherwise take the cores from NUTS's devices) is set before a command's
    imports load SciPy's OpenBLAS; a CPU device per core, up to NUTS's chains,
    and the persistent compilation cache before any JAX work.

    Equinox's run-time checks (diffrax's of a solve's save times) are host
    callbacks, and JAX's persistent cache stores no program that holds one, so
    the periodic orbits' programs would compile again in every process. Every
    solve here sets ``throw=False`` and reads its result code, so the checks
    are set to give NaN instead (``EQX_ON_ERROR=nan``, unless the user set it;
    equinox reads it when it is first imported, after this).
    """
    os.environ.setdefault(EQX_ON_ERROR[0], EQX_ON_ERROR[1])
    from bayeshopf._preload import available_cores
    from bayeshopf.inference.cache import configure_xla_cpu, enable_compilation_cache

    configure_xla_cpu()
    from bayeshopf._x64 import ensure_x64
    from bayeshopf.inference.collapsed import CollapsedSettings

    configure_xla_cpu(host_devices=min(available_cores(), CollapsedSettings.num_chains))
    enable_compilation_cache()
    ensure_x64()


def load_command(name: str) -> ModuleType:
    """The module of subcommand ``name``, imported after :func:`prepare_runtime`."""
    prepare_runtime()
    return importlib.import_module(COMMANDS[name].module)


def build_parser(full: Iterable[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser.

    Args:
        full: The subcommands whose options are added (their modules imported);
            ``None``: every one. The others get their name and help only.
    """
    full = set(COMMANDS if full is None else full)
    ap = argparse.ArgumentParser(
        prog="bayeshopf",
        description="Bayesian hybrid normal-form models of Hopf bifurcations from "
        "limit-cycle-oscillation recordings.",
    )
    ap.add_argument("--debug", action="store_true", help="show tracebacks of internal errors")
    ap.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, cmd in COMMANDS.items():
        if name in full:
            module = load_command(name)
            s = sub.add_parser(name, help=cmd.help, description=module.DESCRIPTION)
            module.add_arguments(s)
        else:
            s = sub.add_parser(name, help=cmd.help)
        # --debug after the subcommand as well as before it
        s.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="show tracebacks of internal errors")
    return ap


def _command_name(argv: list[str]) -> str | None:
    """The subcommand in ``argv``: its first word that is not an option."""
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    name = _command_name(argv)
    debug = "--debug" in argv
    try:
        chosen = [name] if name in COMMANDS else []
        args = build_parser(chosen).parse_args(argv)
        return importlib.import_module(COMMANDS[args.command].module).run(args)
    except BayesHopfError as e:
        print(f"bayeshopf {name}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"bayeshopf {name}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as e:  # one line unless --debug
        if debug:
            traceback.print_exc()
        else:
            print(f"bayeshopf {name}: internal error: {type(e).__name__}: "
                  f"{str(e).splitlines()[0] if str(e) else ''} (rerun with --debug for details)",
                  file=sys.stderr)
        return EXIT_ERROR


def run() -> None:
    """The console script ``bayeshopf``: :func:`main`, then exit with its code.

    Before the interpreter's teardown it moves every object to the garbage
    collector's permanent generation (:func:`gc.freeze`), so that the teardown's
    collections do not trace the heap of JAX, NumPyro, Matplotlib and ArviZ once
    more. Every file is written and closed by then, and the exit handlers still run.
    """
    code = main()
    gc.freeze()
    sys.exit(code)


if __name__ == "__main__":
    run()

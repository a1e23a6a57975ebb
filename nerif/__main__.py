"""``python -m nerif [overrides]``: one reconstruction, or a multirun with ``-m``."""
import logging
import os
import shlex
import signal
import sys
from pathlib import Path
from typing import Optional

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import OverrideParseException
from omegaconf import DictConfig

from nerif.configs import check_kinds, check_settings, compose, config_dir, group_choices, unknown_override
from nerif.export import write_json
from nerif.io.summary import FAILED


def parallel_jobs() -> int:
    """Jobs running at once on this machine: ``hydra.launcher.n_jobs`` under the joblib launcher (-1: one per
    core, -2: all but one, as joblib counts), else 1 (one job at a time, or one per Slurm allocation)."""
    launcher = HydraConfig.get().launcher
    n = launcher.get("n_jobs") if "joblib" in str(launcher.get("_target_", "")) else None
    if n is None:
        return 1
    return max(1, n if n > 0 else (os.cpu_count() or 1) + 1 + n)


def check_overrides(cfg: DictConfig, overrides) -> None:
    """One sentence for a command-line setting of the wrong kind (:func:`nerif.configs.check_kinds`, against the
    config of the same config-group choices), or one the run ignores: the synthetic rig's (``rig.*``) with
    recorded data, whose cameras come from the data's own files."""
    try:
        defaults = compose(group_choices(overrides))
    except Exception as e:  # a launcher that left Hydra's config search uninitialised: the components check
        logging.getLogger("nerif").debug("the settings' kinds are not checked here: %s", e)
        defaults = None
    if defaults is not None:
        check_kinds(cfg, defaults, overrides)
    if "rig" in cfg.data:  # the dataset builds its cameras from the rig group
        return
    ignored = [o for o in overrides if o.lstrip("+~").startswith("rig.")]
    if ignored:
        binning = " (the binning of recorded data is data.binning)" if any("binning" in o for o in ignored) else ""
        raise ValueError(f"{', '.join(ignored)}: rig.* describes the synthetic rig; data={cfg.data.name} takes its "
                         f"cameras from its own files{binning}")


def unreadable_override(args: list[str]) -> Optional[str]:
    """One sentence for the first command-line override whose value Hydra's grammar cannot read as written (a path
    with a space, a bracket, an accent, ``=``, ``~`` or an apostrophe), with the quoted form it reads; None."""
    parser = OverridesParser.create()
    for arg in args:
        if arg.startswith("-") or "=" not in arg:
            continue
        try:
            parser.parse_overrides([arg])
        except OverrideParseException:
            key, value = arg.split("=", 1)
            quoted = shlex.quote(key + '="' + value.replace("\\", "\\\\").replace('"', '\\"') + '"')
            return (f"{arg}: Hydra cannot read this value as written (a space, a bracket, an accent, '=', '~' or a "
                    f"quote in it); quote it for Hydra, inside the shell's quotes: {quoted}")
    return None


def stop(message: str) -> float:
    """Log ``message`` as the run's one sentence and end it: a multirun's job is listed as failed and the sweep
    goes on; a single run exits with status 2."""
    logging.getLogger("nerif").error("%s", message)
    if HydraConfig.get().mode.name == "MULTIRUN":  # the sweep goes on; its summary lists the job as failed
        write_json({"error": message}, Path(HydraConfig.get().runtime.output_dir) / FAILED)
        return float("nan")
    sys.exit(2)


def interrupted(e: KeyboardInterrupt) -> None:
    """The exit of a run a signal ended: where training had begun, the loop saved a checkpoint and said so in one
    line (a Slurm requeue handed on); before it (the flow, the rendering) nothing was made to keep."""
    from nerif.solvers import Interrupted

    if not isinstance(e, Interrupted):
        logging.getLogger("nerif").error("interrupted before training began: nothing to save")
        sys.exit(130)
    number = getattr(signal, e.signal_name)
    launcher_handler = signal.getsignal(number)
    if e.signal_name == "SIGUSR2" and callable(launcher_handler):  # submitit's: it requeues the job, which
        launcher_handler(number, None)                            # resumes from this checkpoint
    sys.exit(128 + int(number))


def sentence(e: Exception) -> str:
    """The one sentence bad input raised: its message (an ``OSError``'s own: "[Errno 2] ...: 'path'")."""
    return str(e.args[0] if len(e.args) == 1 else e)


def diverged(e: Exception) -> str:
    """The one sentence of a run whose loss diverged (:class:`nerif.solvers.DivergenceError`), else ""."""
    from nerif.solvers import DivergenceError

    return sentence(e) if isinstance(e, DivergenceError) else ""


def refused(args: list[str]) -> Optional[str]:
    """The sentence for command-line ``args`` refused before Hydra composes anything (an override its grammar
    cannot read, a group option or setting nerif does not have); None."""
    return unreadable_override(args) or unknown_override(args)


def execute(cfg: DictConfig, overrides: list[str], out_dir: Path, jobs: int = 1) -> dict:
    """A run of the composed ``cfg`` into ``out_dir``: the command line's ``overrides`` checked by kind, the config
    by what it alone tells (before the seconds of importing torch and the rest), then :func:`nerif.app.run` with
    ``jobs`` running at once; its metrics. Bad input raises ``ValueError`` (or ``FileNotFoundError``) with the one
    sentence (:func:`sentence`)."""
    check_overrides(cfg, overrides)
    check_settings(cfg)
    from nerif.app import run

    return run(cfg, out_dir, jobs)


@hydra.main(version_base=None, config_path=str(config_dir()), config_name="config")
def main(cfg: DictConfig) -> float:
    try:
        metrics = execute(cfg, HydraConfig.get().overrides.task, HydraConfig.get().runtime.output_dir,
                          parallel_jobs())
    except (ValueError, FileNotFoundError) as e:  # bad input: one sentence
        return stop(sentence(e))
    except KeyboardInterrupt as e:
        interrupted(e)
    except Exception as e:  # a diverged run, and anything else, is one sentence too; the traceback with debug=true
        said = diverged(e)
        if not said and cfg.get("debug"):
            raise
        from nerif.app import unexpected

        return stop(said or unexpected(e, "debug=true"))
    return metrics.get("temperature_rmse_K", metrics["deflection_rmse"])


def cli() -> None:
    """``python -m nerif``: an override Hydra cannot read is one sentence (Hydra's own is its grammar's), then the
    run."""
    message = refused(sys.argv[1:])
    if message:
        print(f"nerif: {message}", file=sys.stderr)
        sys.exit(2)
    main()


if __name__ == "__main__":
    cli()

"""``python -m nerif [overrides]``: one reconstruction, or a multirun with ``-m``."""
import logging
import sys

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from nerif.app import run
from nerif.configs import config_dir
from nerif.solvers import DivergenceError


@hydra.main(version_base=None, config_path=str(config_dir()), config_name="config")
def main(cfg: DictConfig) -> float:
    try:
        metrics = run(cfg, HydraConfig.get().runtime.output_dir)
    except (ValueError, FileNotFoundError, DivergenceError) as e:  # bad input or a diverged run: one sentence
        logging.getLogger("nerif").error("%s", e.args[0] if e.args else e)
        if HydraConfig.get().mode.name == "MULTIRUN":
            return float("nan")
        sys.exit(2)
    return metrics.get("temperature_rmse_K", metrics["deflection_rmse"])


if __name__ == "__main__":
    main()

"""Evaluate a model: ``python eval.py +experiment=wasb_padel ckpt_path=PATH`` (see conf/eval.yaml)."""
import os
from pathlib import Path

import hydra
from omegaconf import DictConfig

os.environ.setdefault("PROJECT_ROOT", str(Path(__file__).resolve().parent))


@hydra.main(version_base="1.3", config_path="conf", config_name="eval")
def main(cfg: DictConfig) -> None:
    from training.preflight import check_data, require_eval_weights

    require_eval_weights(cfg)  # before the data: the default dataset takes minutes to make
    check_data(cfg)
    from training.run import evaluate

    evaluate(cfg)


if __name__ == "__main__":
    main()

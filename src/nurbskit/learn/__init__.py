"""Small networks that nurbskit trains itself, on data it generates (issues 10 and 11).

One training loop serves every model (:func:`~nurbskit.learn.trainer.train`): batches come
from a deterministic generator keyed by (seed, step), so a run resumed from its checkpoint
sees exactly the batches it would have seen without the interruption. Trained weights ship
inside the package (``nurbskit/learn/weights/<name>.pt``) and load with
:func:`~nurbskit.learn.weights.load_weights`; each file records the command, seed, steps
and seconds that made it.
"""

from .trainer import TrainConfig, TrainRun, batch_generator, train
from .weights import load_weights, save_weights, shipped_weights, weights_path

__all__ = ["TrainConfig", "TrainRun", "batch_generator", "train", "load_weights", "save_weights",
           "shipped_weights", "weights_path"]

"""Figures (matplotlib loads only when a plotting function is called)."""

_NAMES = ("plot_wireframe", "plot_clouds", "plot_error_map", "plot_loss", "plot_fit_panels",
          "plot_training")


def __getattr__(name: str):
    if name in _NAMES:
        from . import plots

        return getattr(plots, name)
    raise AttributeError(f"module 'nurbskit.viz' has no attribute {name!r}")


__all__ = list(_NAMES)

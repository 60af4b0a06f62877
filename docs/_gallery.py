"""Per-example set-up of the gallery (``sphinx_gallery_conf["reset_modules"]`` in conf.py).

A module, not a function in conf.py, so that Sphinx can pickle the configuration.
"""


def reset(gallery_conf, fname):
    """Run each example with pyvista off-screen and matplotlib's figures closed."""
    import matplotlib.pyplot as plt

    plt.close("all")
    try:
        import pyvista
    except ImportError:  # the [render] extra is part of [docs]; without it, no 3-D pictures
        return
    pyvista.OFF_SCREEN = True
    pyvista.set_plot_theme("document")

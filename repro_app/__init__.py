"""The app layer: the `repro` command line, the report and the main job (`repro reproduce`).

Layers import one way (tests/test_layers.py checks it): core (config, run format, envs, agent, replay,
offline data) <- training and launch (trainer, api, bench, launch/) <- analysis <- paper_figures <- this
package. Nothing below imports from here.
"""

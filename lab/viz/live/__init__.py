"""Live views of a run: watch the robot think, in JupyterLab, in a window, or in a recording.

One drawing code path (:meth:`LiveView.render`, a matplotlib figure drawn by Agg into an RGB array)
feeds three sinks: an ``ipywidgets.Image`` (PNG bytes) for a notebook, a :class:`~lab.viz.recorder.Recorder`
for ``--record``, and a matplotlib window when a display exists. The view is an *observer*: the agents
call it once per step (identification) or per event (search) and it draws at most ``rate_hz`` times per
second of **sim time**, so a run is never blocked on it; a run with no view asked for draws nothing
(the agents' observer is ``None``; this module is not even imported).

Identification (the paper's Fig. 6 visual interface, live)::

    from lab.viz.live import LiveView
    agent = build_agent(robot, planner="lut")     # lab.runs.identify: the agent with its databases and tables
    view = LiveView.for_identification(agent)   # hooks itself in as the agent's observer
    display(view.widget)                        # an ipywidgets.Image, refreshed at 2 Hz of sim time
    agent.run()

Panels (:mod:`lab.viz.live.identification`): the top-down scene with the ring of candidate poses, the
left camera image with the matches and the estimated pose, the model probabilities against time.

The whole episode of ``lab identify`` with the box driven by hand (``attach`` is called once the agent
and the carrier exist, before the run)::

    from lab.runs.identify import run_identify
    from lab.viz.live import LiveView, TeleopPanel

    def attach(agent, carrier):
        display(LiveView.for_identification(agent).widget, TeleopPanel(carrier.mover).widget)

    run = in_background(run_identify, 1, mover="teleop", attach=attach)   # returns at once
    ...                                  # press the buttons while it runs
    result = run.result()                # waits for the end of the episode

A notebook handles a widget's clicks only while no cell is running: :func:`in_background` runs the
episode in a worker thread so the teleoperation buttons work during the run (the view's picture is
updated from the worker; a plain ``run_identify(...)`` in a cell shows the view but queues the clicks).

Search::

    view = LiveView.for_search(agent)           # agent: a SearchAgent; its navigate may carry .navigator
    display(view.widget)
    agent.run()
    # or the whole trial: run_search(..., attach=lambda agent: display(LiveView.for_search(agent).widget))

Panels (:mod:`lab.viz.live.search`): the probability map ``M_p``, the costmap ``M_c`` with the planned
path, the camera image of the last global or local search.

Recording: ``LiveView.for_identification(agent, rate_hz=None, recorder=Recorder("run.gif"),
widget=False)`` draws every step into the recorder (one frame per step, sim time stamped); close the
recorder after the run to write the file. A second view (a notebook's) chains after it.

Cost: the axes are drawn once and the data blitted over them (a full redraw only when a limit moves, in
coarse steps), and the status lines are drawn with OpenCV: about 20-25 ms of CPU per picture at
960 x 540 px, plus ~5 ms for the widget's PNG; ``benchmarks/bench_live.py`` measures the share of a
run's wall time at the default 2 Hz.

Teleoperation of the moving box is :class:`~lab.viz.teleop.TeleopPanel` (``TeleopPanel(mover).widget``,
importable from here too): buttons that drive the :class:`~lab.sim.movers.TeleopMover`'s carrier robot
and turn the box on it.

The modules: :mod:`~lab.viz.live.view` (the loop: rate in sim time, widget, recorder, window),
:mod:`~lab.viz.live.canvas` (the blitted figure and its OpenCV status texts), the two views' panels
(:mod:`~lab.viz.live.identification`, :mod:`~lab.viz.live.search`).

The view reads only what the agent has (its records, filters and frames), never the simulator's truth.
"""

from lab.viz.live.identification import IdentificationPanels, identification_inliers
from lab.viz.live.search import SearchPanels
from lab.viz.live.view import LiveView, in_background
from lab.viz.teleop import TeleopPanel, TeleopSpeeds

__all__ = [
    "IdentificationPanels",
    "LiveView",
    "SearchPanels",
    "TeleopPanel",
    "TeleopSpeeds",
    "identification_inliers",
    "in_background",
]

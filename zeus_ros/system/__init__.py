"""What runs the live system: the node plan and its defaults, the processes, restarts, progress.

`zeus launch`, `zeus demo`, `ros2 launch zeus_ros zeus.launch.py` and the test harness start
the nodes through these modules:

- launch_defaults: which nodes start with which parameters (`plan()`), the launch arguments
  and their defaults, the package share; the one source of both `zeus launch` and the ros2
  launch file;
- processes: node processes with the project's environment (loopback discovery, one domain id
  per group), started and stopped one way (SIGINT, then SIGTERM, then SIGKILL);
- respawn: the restart policy per node (limit, window, back-off);
- launch_progress: `zeus launch`'s status line (a subscriber to the step topics).
- continual_settings, continual_watch: what the continual trainer node needs of continual
  deployment without the training code (its settings, the history file, the live check after
  a swap, the novelty alarm, the recording's retention); its training round
  (offline/training/continual.py, in a child process) shares the settings and the history.

The command lines themselves live in zeus_ros/cli/ (launch.py, demo.py); nothing here parses
a command line.
"""

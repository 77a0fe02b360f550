"""What runs on the host computer: the ``rosgate`` command line, the simulator runner, the
co-simulation of a project with the ReconOS runtime model, the ROS 1 master, node and RBCP
client of hardware ROS nodes, and the TAP bridge between simulated hardware and the Linux
kernel's network stack."""

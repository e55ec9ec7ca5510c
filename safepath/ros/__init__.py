"""ROS 2 interface of safepath."""

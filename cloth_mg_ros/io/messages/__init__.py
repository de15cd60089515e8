"""ROS 2 messages as bytes, without rclpy: plain CDR written and read straight from numpy
(`cdr`), the cloth's visualization_msgs/Marker TRIANGLE_LIST (`markers`). The node publishes
these bytes (ros/), the batch runner and the benchmarks write them into bags (rosbags); rclpy
is imported only by the functions that check the layouts against its serialiser."""

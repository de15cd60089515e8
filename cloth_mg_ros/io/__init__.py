"""What goes in and out of files: rosbag2 bags of body poses and joints (`bags`),
the Azure Kinect driver's body tracking MarkerArray (`kinect_markers`), the packaged config/ and
bags/ (`share`), pictures (`render`), text tables (`text_table`) and ROS messages as bytes
(`messages`: CDR and marker builders, no rclpy).
"""

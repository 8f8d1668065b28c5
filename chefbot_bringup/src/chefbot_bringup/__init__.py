"""Robot-PC stack: LaunchPad serial driver, differential-drive nodes (twist_to_motors,
pid_velocity, diff_tf), keyboard teleop, depth image to laser scan.
"""

"""Fleet-scale friction identification: many robots, many joints, one run per joint per day.

:mod:`.table` is the contract of the fleet table (schema, reading, atomic writing); the fitting
side (discovery, one run's rows, the Dask driver) and the trend side read and write only that.
Pure: no rclpy.
"""

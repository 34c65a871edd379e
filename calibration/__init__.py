"""imutool calibration: magnetometer hard/soft iron, deviation card, gyro/accel bias and scale, Allan noise,
and the calibration file (TOML) applied by every command that reads sensor data. Knows nothing of the CLI."""

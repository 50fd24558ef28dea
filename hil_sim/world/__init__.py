"""The truth models: the world parameters, rigid body and wheels, environment torques, the geomagnetic field,
eclipses, the orbit, Sun and Moon truth, the IMU and star tracker, and the disturbance budget."""

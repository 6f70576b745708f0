"""The world a run happens in: specs (config), terrain, maps, situations, the simulator's
observations, and the paper-style figure of a situation. Nothing here knows of controllers,
runs or stores."""

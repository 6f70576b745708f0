"""Running many situations: a campaign spec's jobs (pure functions of spec, seed and index),
the executors that run them (Rust threads, a process pool, Ray) and the campaign that stores
them."""

"""Dr.Jit twins of the host renderer, under the names of their host originals (the GPU path;
on the CPU they run on ``llvm_ad_rgb``, which is how the tests check them against the host):

* :mod:`~virtus.render.jit.tracing` -- device-resident passes (``DeviceTrace``, ``DeviceFrames``).
* :mod:`~virtus.render.jit.synthesis` -- every frame of a pose synthesised and digitised in one
  kernel (a lane per pixel on the CPU, a lane per frame and pixel on the GPU).
* :mod:`~virtus.render.jit.noise` -- the sensor's counter-based noise streams on the device.
* :mod:`~virtus.render.jit.decode` -- fringe decoding on the device.
"""

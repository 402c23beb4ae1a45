import torch

# The guard's models are tiny: one thread is fastest on a shared CPU.
torch.set_num_threads(1)

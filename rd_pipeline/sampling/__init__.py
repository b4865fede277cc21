"""Motion sampling: 1 s segments and their statistics, the balanced prior, the bounded-mixture sampler."""

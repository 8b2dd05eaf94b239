"""Who may do what, and how much: trip quotas per API key, address and device, token buckets, and overload shedding
(a worker refuses at once, with 503 and Retry-After, the work it cannot do in time)."""

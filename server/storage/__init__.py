"""Where the service's state lives: open trips (in this process or in Redis), the WebSocket streams held per trip
and client, the queue board's probes, and the one pipelined Redis connection per worker they share."""

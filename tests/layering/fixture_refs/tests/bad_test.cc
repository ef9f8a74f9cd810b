// Reads ../shared/data/lidar/vlp16/packets.pcap directly.

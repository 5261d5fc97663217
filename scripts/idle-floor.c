// The idle control mesh's configured periodic work done with bare syscalls — no
// async runtime, no iceoryx2, no metrics — to measure what that work costs this
// machine at the least (docs/benchmarks.md, the idle mesh's baseline).
//
//   gcc -O2 -o /tmp/idle-floor scripts/idle-floor.c && /tmp/idle-floor 30 [rest]
//
// `rest`: the swarm queue at rest and the pose broadcast asleep, as in the idle
// mesh (nobody listening to the poses): `swarm` and `gc` at 1 Hz.
//
// Processes (CPU from /proc/<pid>/schedstat over the window):
//   sim        50 Hz on the CLOCK_MONOTONIC grid: one TCP send to `link` (28 bytes,
//              every fifth 143), as vehicle-sim's telemetry
//   link       reads it, forwards each read to 127.0.0.1:14550 (UDP, nobody
//              listening, as the shipped ground-station endpoint), copies 120 bytes
//              into shared memory; plus a 2 Hz heartbeat
//   swarm      30 Hz: writes 20 KiB into shared memory (SwarmState)
//   gc         30 Hz, 2 ms after the grid point: reads the 20 KiB, sends an 84-byte
//              datagram to 127.0.0.1:6666 (the pose broadcast)
//   shot       5 Hz: writes 256 bytes
//   6 × heartbeat-only services at 2 Hz, the supervisor's 1 Hz drain
#define _GNU_SOURCE
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/timerfd.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static char *shm;

static double cpu_ms(pid_t p) {
  char f[64];
  unsigned long long ns = 0;
  snprintf(f, sizeof f, "/proc/%d/schedstat", p);
  FILE *x = fopen(f, "r");
  if (x) {
    if (fscanf(x, "%llu", &ns) != 1) ns = 0;
    fclose(x);
  }
  return ns / 1e6;
}

// A periodic timerfd on the grid of `hz` points a second, `offset_us` after each.
static int ticker(int hz, int offset_us) {
  int tf = timerfd_create(CLOCK_MONOTONIC, 0);
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  struct itimerspec it = {0};
  it.it_value.tv_sec = t.tv_sec + 1;
  it.it_value.tv_nsec = offset_us * 1000L;
  if (hz == 1) it.it_interval.tv_sec = 1;
  else it.it_interval.tv_nsec = 1000000000L / hz;
  timerfd_settime(tf, TFD_TIMER_ABSTIME, &it, NULL);
  return tf;
}

static int epoll_on(int fd, unsigned tag) {
  int ep = epoll_create1(0);
  struct epoll_event e = {.events = EPOLLIN, .data.u32 = tag};
  epoll_ctl(ep, EPOLL_CTL_ADD, fd, &e);
  return ep;
}

static struct sockaddr_in loopback(int port) {
  struct sockaddr_in a = {0};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(0x7f000001);
  a.sin_port = htons(port);
  return a;
}

// Wakes at `hz`; writes (or, `read_back`, reads) `bytes` of shared memory; sends an
// 84-byte datagram to `udp_port` if non-zero.
static void timer_loop(int hz, int offset_us, int bytes, int udp_port, int read_back) {
  int tf = ticker(hz, offset_us), ep = epoll_on(tf, 0);
  int us = socket(AF_INET, SOCK_DGRAM, 0);
  struct sockaddr_in g = loopback(udp_port);
  static char buf[32768];
  for (;;) {
    struct epoll_event o;
    unsigned long long n;
    epoll_wait(ep, &o, 1, -1);
    if (read(tf, &n, 8) < 0) continue;
    if (read_back) memcpy(buf, shm, bytes);
    else memset(shm, 1, bytes);
    if (udp_port) sendto(us, buf, 84, 0, (void *)&g, sizeof g);
  }
}

int main(int argc, char **argv) {
  int secs = argc > 1 ? atoi(argv[1]) : 30;
  if (secs < 1) secs = 30;
  int rest = argc > 2 && !strcmp(argv[2], "rest");
  int swarm_hz = rest ? 1 : 30;
  shm = mmap(NULL, 1 << 20, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
  pid_t pids[16];
  const char *names[16];
  int np = 0;

  struct sockaddr_in a = loopback(0);
  socklen_t len = sizeof a;
  int lfd = socket(AF_INET, SOCK_STREAM, 0);
  bind(lfd, (void *)&a, sizeof a);
  listen(lfd, 1);
  getsockname(lfd, (void *)&a, &len);
  int sfd = socket(AF_INET, SOCK_STREAM, 0);
  connect(sfd, (void *)&a, sizeof a);
  int rfd = accept(lfd, NULL, NULL), one = 1;
  setsockopt(sfd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);

  if (!(pids[np] = fork())) {
    int tf = ticker(50, 0), ep = epoll_on(tf, 0), i = 0;
    char m[143];
    memset(m, 7, sizeof m);
    for (;;) {
      struct epoll_event o;
      unsigned long long n;
      epoll_wait(ep, &o, 1, -1);
      if (read(tf, &n, 8) < 0) continue;
      send(sfd, m, (i++ % 5 == 0) ? 143 : 28, MSG_NOSIGNAL);
    }
  }
  names[np++] = "sim 50 Hz";
  if (!(pids[np] = fork())) {
    int ep = epoll_on(rfd, 0), hb = ticker(2, 0);
    struct epoll_event e = {.events = EPOLLIN, .data.u32 = 1};
    epoll_ctl(ep, EPOLL_CTL_ADD, hb, &e);
    int us = socket(AF_INET, SOCK_DGRAM, 0);
    struct sockaddr_in g = loopback(14550);
    char buf[4096];
    for (;;) {
      struct epoll_event o;
      epoll_wait(ep, &o, 1, -1);
      if (o.data.u32 == 1) {
        unsigned long long n;
        if (read(hb, &n, 8) > 0) memset(shm + 4096, 1, 64);
        continue;
      }
      int n = recv(rfd, buf, sizeof buf, MSG_DONTWAIT);
      if (n <= 0) continue;
      sendto(us, buf, n, 0, (void *)&g, sizeof g);
      memcpy(shm + 8192, buf, 120);
    }
  }
  names[np++] = "link";
  if (!(pids[np] = fork())) timer_loop(swarm_hz, 0, 20480, 0, 0);
  names[np++] = rest ? "swarm 1 Hz" : "swarm 30 Hz";
  if (!(pids[np] = fork())) timer_loop(swarm_hz, 2000, 20480, 6666, 1);
  names[np++] = rest ? "gc 1 Hz + UDP" : "gc 30 Hz + UDP";
  if (!(pids[np] = fork())) timer_loop(5, 0, 256, 0, 0);
  names[np++] = "shot 5 Hz";
  for (int k = 0; k < 6; k++) {
    if (!(pids[np] = fork())) timer_loop(2, 0, 64, 0, 0);
    names[np++] = "heartbeat 2 Hz";
  }
  if (!(pids[np] = fork())) timer_loop(1, 500000, 640, 0, 1);
  names[np++] = "supervisor 1 Hz";
  close(sfd);
  close(rfd);

  sleep(3);
  double c0[16], total = 0;
  for (int i = 0; i < np; i++) c0[i] = cpu_ms(pids[i]);
  sleep(secs);
  for (int i = 0; i < np; i++) {
    double d = cpu_ms(pids[i]) - c0[i];
    total += d;
    printf("%-16s %.3f %% of one core\n", names[i], d / (secs * 10.0));
  }
  printf("total            %.2f %% of one core over %d s\n", total / (secs * 10.0), secs);
  for (int i = 0; i < np; i++) kill(pids[i], SIGKILL);
  while (wait(NULL) > 0) {}
  return 0;
}

/*
 * LD_PRELOAD shim: bind() to the "any" address becomes bind() to loopback.
 *
 * Why: roscpp's XML-RPC server (xmlrpcpp's XmlRpcSocket::bind(fd, port)) always
 * binds INADDR_ANY and ignores ROS_IP/ROS_HOSTNAME, so every C++ node (rosout,
 * robot_state_publisher, rviz) would accept XML-RPC calls (shutdown,
 * publisherUpdate, ...) from the whole network even in a loopback-only setup.
 * rospy, rosmaster and roscpp's TCPROS server already honour a loopback
 * ROS_IP; this closes the one gap.  tools/env.sh preloads it only while the
 * workspace runs loopback-only (CHEFBOT_ROS_IP unset).  Built by tools/setup.sh.
 *
 * Only wildcard addresses change (0.0.0.0 -> 127.0.0.1, :: -> ::1); binds to a
 * specific address, Unix sockets and everything else pass through untouched.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <netinet/in.h>
#include <string.h>
#include <sys/socket.h>

typedef int (*bind_fn)(int, const struct sockaddr *, socklen_t);

int bind(int fd, const struct sockaddr *addr, socklen_t len)
{
    static bind_fn real_bind;
    if (!real_bind)
        real_bind = (bind_fn)dlsym(RTLD_NEXT, "bind");
    if (addr && addr->sa_family == AF_INET && len >= (socklen_t)sizeof(struct sockaddr_in)) {
        struct sockaddr_in in4;
        memcpy(&in4, addr, sizeof in4);
        if (in4.sin_addr.s_addr == htonl(INADDR_ANY)) {
            in4.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
            return real_bind(fd, (const struct sockaddr *)&in4, sizeof in4);
        }
    } else if (addr && addr->sa_family == AF_INET6 && len >= (socklen_t)sizeof(struct sockaddr_in6)) {
        struct sockaddr_in6 in6;
        memcpy(&in6, addr, sizeof in6);
        if (memcmp(&in6.sin6_addr, &in6addr_any, sizeof in6.sin6_addr) == 0) {
            in6.sin6_addr = in6addr_loopback;
            return real_bind(fd, (const struct sockaddr *)&in6, sizeof in6);
        }
    }
    return real_bind(fd, addr, len);
}

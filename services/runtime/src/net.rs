//! Small socket helpers shared by the gateways' client sides (tools and tests).

use std::net::{IpAddr, SocketAddr};

use tokio::net::{TcpSocket, TcpStream};

/// Connects to `addr`, from the local address `from` when given (port chosen by the
/// system; e.g. `127.0.0.2` to look like another machine on loopback), with
/// `TCP_NODELAY` set: protocol clients send small records and want them sent now.
pub async fn connect_tcp(addr: SocketAddr, from: Option<IpAddr>) -> std::io::Result<TcpStream> {
    let stream = match from {
        None => TcpStream::connect(addr).await?,
        Some(from) => {
            let socket = if from.is_ipv4() {
                TcpSocket::new_v4()?
            } else {
                TcpSocket::new_v6()?
            };
            socket.bind(SocketAddr::new(from, 0))?;
            socket.connect(addr).await?
        }
    };
    stream.set_nodelay(true)?;
    Ok(stream)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn connects_from_the_given_local_address() {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let from: IpAddr = "127.0.0.2".parse().unwrap();
        let (client, accepted) = tokio::join!(connect_tcp(addr, Some(from)), listener.accept());
        let client = client.unwrap();
        assert!(client.nodelay().unwrap());
        assert_eq!(accepted.unwrap().1.ip(), from);
    }
}
